#version 430
// Radiance of the environment (at infinity) seen through an OpenCV pinhole camera.
// The environment is an angle map extended past its rim (so bilinear lookups near -z stay inside).

uniform sampler2D probe;        // angle map, row 0 of the image uploaded first (t = 1 at the top)
uniform mat3 camera_to_world;   // OpenCV camera axes (x right, y down, z forward) to world
uniform vec4 intrinsics;        // fx, fy, cx, cy in pixels
uniform vec2 image_size;        // width, height in pixels

out vec4 radiance;

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

void main() {
    // OpenCV pixel coordinates: centres at integers, row 0 at the top; GL's origin is bottom left.
    vec2 pixel = vec2(gl_FragCoord.x - 0.5, image_size.y - gl_FragCoord.y - 0.5);
    vec3 ray = normalize(vec3((pixel.x - intrinsics.z) / intrinsics.x, (pixel.y - intrinsics.w) / intrinsics.y, 1.0));
    vec2 st = anglemap_st(camera_to_world * ray);
    // Texture row 0 is the image's top row, at t = 1: flip t for the lookup.
    radiance = vec4(texture(probe, vec2(st.x, 1.0 - st.y)).rgb, 1.0);
}
