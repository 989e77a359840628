// The scene a pixel sees: the environment and, along the AR path, the table with its printed tag.
// Shared by the view and camera-frame shaders (prepended after the #version line).
// The environment is an angle map extended past its rim (so bilinear lookups near -z stay inside).

uniform sampler2D probe;        // angle map, row 0 of the image uploaded first (t = 1 at the top)
uniform sampler2D rays;         // per pixel, its unit ray in OpenCV camera axes (lens distortion included);
                                // w: its vignetting in the camera pass
uniform mat3 camera_to_world;   // OpenCV camera axes (x right, y down, z forward) to world

// The table top (y = 0) with the printed tag (sensors/table.py), for views along the AR path: compiled
// in where TABLE is defined, so that the views of the sweep carry none of its cost.
#ifdef TABLE
uniform vec3 camera_position;   // world, metres
uniform vec2 table_half;        // half its size along x and z
uniform vec3 table_albedo;
uniform vec3 table_light;       // M_1(+y) of the environment: radiance of a white matte surface facing up
uniform float paper_half;       // half the side of the printed sheet
uniform sampler2D paper;        // its reflectance, row 0 towards world -z (mipmapped)
#endif

vec3 world_ray(ivec2 pixel) {
    return camera_to_world * texelFetch(rays, pixel, 0).xyz;
}

#ifdef TABLE
// Where a camera ray meets the table top y = 0 (its x, z), or false where it points up.
bool table_hit(vec3 d, out vec2 hit) {
    hit = vec2(0.0);
    if (!(d.y < 0.0 && camera_position.y > 0.0)) return false;
    hit = camera_position.xz - (camera_position.y / d.y) * d.xz;
    return true;
}
#endif

// Radiance seen by image pixel (column x, row y) along its world ray d; the ray texture holds the
// image's top row first. Texture row 0 of the probe is the angle map's top row, at t = 1.
vec3 radiance_along(ivec2 pixel, vec3 d) {
#ifdef TABLE
    {
        vec2 hit;
        if (table_hit(d, hit) && all(lessThanEqual(abs(hit), table_half))) {
            vec2 uv = hit / (2.0 * paper_half) + 0.5;  // u along +x, v along +z (image rows)
            if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) return table_albedo * table_light;
            // The sheet's footprint between this pixel and its neighbours (both shader kinds compute it
            // the same way, without screen-space derivatives) picks the mip level.
            ivec2 size = textureSize(rays, 0);
            ivec2 nx = pixel + ivec2(pixel.x + 1 < size.x ? 1 : -1, 0);
            ivec2 ny = pixel + ivec2(0, pixel.y + 1 < size.y ? 1 : -1);
            vec2 hx, hy;
            vec2 gx = table_hit(world_ray(nx), hx) ? (hx - hit) / (2.0 * paper_half) : vec2(0.0);
            vec2 gy = table_hit(world_ray(ny), hy) ? (hy - hit) / (2.0 * paper_half) : vec2(0.0);
            return textureGrad(paper, uv, gx, gy).r * table_light;
        }
    }
#endif
    vec2 st = anglemap_st(d);
    return texture(probe, vec2(st.x, 1.0 - st.y)).rgb;
}

vec3 pixel_radiance(ivec2 pixel) {
    return radiance_along(pixel, world_ray(pixel));
}
