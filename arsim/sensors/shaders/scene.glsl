// The scene a pixel sees: the environment and, along the AR path, the table with its printed tag.
// Shared by the view and camera-frame shaders (prepended after the #version line).
// The environment is an angle map extended past its rim (so bilinear lookups near -z stay inside).

uniform sampler2D probe;        // angle map, row 0 of the image uploaded first (t = 1 at the top)
uniform sampler2D rays;         // per pixel, its unit ray in OpenCV camera axes (lens distortion included)
uniform mat3 camera_to_world;   // OpenCV camera axes (x right, y down, z forward) to world

// The table top (y = 0) with the printed tag (sensors/table.py), for views along the AR path.
uniform bool table_enabled;
uniform vec3 camera_position;   // world, metres
uniform vec2 table_half;        // half its size along x and z
uniform vec3 table_albedo;
uniform vec3 table_light;       // M_1(+y) of the environment: radiance of a white matte surface facing up
uniform float paper_half;       // half the side of the printed sheet
uniform sampler2D paper;        // its reflectance, row 0 towards world -z (mipmapped)

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
    vec3 d = camera_to_world * ray;
    if (table_enabled) {
        // Where the ray meets y = 0 (computed for every pixel, so that the texture derivatives that
        // pick the mip level are defined everywhere; rays that go up get a far-away dummy point).
        bool down = d.y < 0.0 && camera_position.y > 0.0;
        float t = down ? -camera_position.y / d.y : 0.0;
        vec2 hit = camera_position.xz + t * d.xz;
        vec2 uv = hit / (2.0 * paper_half) + 0.5;  // u along +x, v along +z (image rows)
        vec3 sheet = vec3(textureGrad(paper, uv, dFdx(uv), dFdy(uv)).r);
        if (down && all(lessThanEqual(abs(hit), table_half))) {
            bool on_paper = all(greaterThanEqual(uv, vec2(0.0))) && all(lessThanEqual(uv, vec2(1.0)));
            return (on_paper ? sheet : table_albedo) * table_light;
        }
    }
    vec2 st = anglemap_st(d);
    return texture(probe, vec2(st.x, 1.0 - st.y)).rgb;
}
