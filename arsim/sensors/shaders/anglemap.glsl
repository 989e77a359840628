// Shared by the environment shaders (prepended after the #version line).
// The environment is an angle map extended past its rim (so bilinear lookups near -z stay inside).

uniform sampler2D probe;        // angle map, row 0 of the image uploaded first (t = 1 at the top)
uniform sampler2D rays;         // per pixel, its unit ray in OpenCV camera axes (lens distortion included)
uniform mat3 camera_to_world;   // OpenCV camera axes (x right, y down, z forward) to world

const float PI = 3.14159265358979;

// Thesis Alg. 2.2 (angle-map coordinates of a direction) with its guard: the azimuth is undefined
// at -z, which maps to the rim point (0.5, 1); +z maps to the centre.
vec2 anglemap_st(vec3 d) {
    float b = length(d.xy);
    if (b <= 0.0) {
        return d.z < 0.0 ? vec2(0.5, 1.0) : vec2(0.5, 0.5);
    }
    float a = atan(b, d.z);
    return vec2(0.5) + 0.5 * (d.xy / b) * (a / PI);
}

// Radiance seen by this fragment's pixel. Fragment (x, y) is image pixel (column x, row y): the ray
// texture holds the image's top row first, and so does the framebuffer when read back. Texture row 0
// of the probe is the angle map's top row, at t = 1.
vec3 pixel_radiance() {
    vec3 ray = texelFetch(rays, ivec2(gl_FragCoord.xy), 0).xyz;
    vec2 st = anglemap_st(camera_to_world * ray);
    return texture(probe, vec2(st.x, 1.0 - st.y)).rgb;
}
