// Thesis Alg. 5.1 (image-based lighting with an irradiance and a reflection map), 5.2 (an ambient-
// occlusion light map multiplied into the diffuse part, where LIGHT_MAP is defined) and 5.4 (a
// tangent-space normal map, where NORMAL_MAP is defined). Writes the HDR colour, its alpha the mask (1
// where an object is drawn: the tile is zero elsewhere); with DEBUG, also the vectors it shaded with, for the NumPy reference to shade the same pixels. With
// SPHERE_IMPOSTOR the fragment ray-casts a sphere through its quad (sphere.vert): the hit's normal, and
// the hit's depth.
uniform sampler2D irradiance_map;   // M_1, angle map extended past its rim
uniform sampler2D reflection_map;   // M_s for this material's exponent
uniform vec3 kd;
uniform vec3 ks;
uniform vec3 eye;                   // camera centre, world
#ifdef LIGHT_MAP
uniform sampler2D light_map;
uniform float light_map_lod;        // its mip level for this object this frame (renderer.py: one level
                                    // per object is far cheaper on llvmpipe than one per pixel)
#endif
#ifdef NORMAL_MAP
uniform sampler2D normal_map;
uniform float normal_map_lod;
#endif
#ifdef VOLUME
uniform sampler3D volume[9];        // an irradiance volume: per grid point the convolved SH of bands 0-2
uniform vec3 volume_low;            // (world axes), a texture per coefficient; the grid spans low..high
uniform vec3 volume_high;
uniform vec3 volume_size;           // grid points per axis
const float VOLUME_PI = 3.14159265358979;
#endif
#ifdef INM
uniform sampler2DArray coefficient_map;  // a layer per basis coefficient of the irradiance (second UV set)
uniform float coefficient_map_lod;
uniform int inm_terms;              // the spec's level of detail: the leading terms summed
#endif
#ifdef PRT_VERTEX
in vec3 v_prt[BASIS_COUNT];         // precomputed radiance transfer relit per vertex (object.vert)
#endif
#ifdef GGX
uniform samplerCube ggx_map;        // the light's GGX prefiltered radiance, level p at roughness p / (levels - 1)
uniform sampler2D brdf_lut;         // the split sum's (A, B): n.v across (s), perceptual roughness up (t)
uniform vec3 f0;                    // mix(0.04, base_color, metallic)
uniform float roughness;            // perceptual
uniform float ggx_levels;
#endif
#ifdef SPHERE_IMPOSTOR
uniform vec3 center;                // world
uniform float radius;
uniform mat4 view_projection;
#endif

in vec3 v_world;
in vec3 v_normal;
in vec3 v_tangent;
in vec2 v_uv;
in vec2 v_uv2;

layout(location = 0) out vec4 hdr;
#ifdef DEBUG
layout(location = 1) out vec4 debug_normal;
layout(location = 2) out vec4 debug_incident;
#endif

// The map's value in direction d: bilinear between texel centres, in an angle-map texture whose row 0 is
// the map's top row (t = 1) and whose texels outside the disk repeat the rim. GPU texture units filter
// with 8-bit weights, which on a sharp reflection map would move a value by a few 1e-4 of itself, against
// the 1e-3 the GL path is held to: there the weights are computed here in float. llvmpipe filters in
// float (FLOAT_FILTERING): its texture unit gives the same values, a quarter faster.
vec3 lookup(sampler2D map, vec3 d) {
    vec2 st = anglemap_st(d);
#ifdef FLOAT_FILTERING
    return texture(map, vec2(st.x, 1.0 - st.y)).rgb;
#else
    ivec2 size = textureSize(map, 0);
    vec2 p = vec2(st.x, 1.0 - st.y) * vec2(size) - 0.5;
    vec2 f = floor(p);
    vec2 a = p - f;
    ivec2 i = ivec2(f);
    ivec2 hi = size - 1;
    vec3 c00 = texelFetch(map, clamp(i, ivec2(0), hi), 0).rgb;
    vec3 c10 = texelFetch(map, clamp(i + ivec2(1, 0), ivec2(0), hi), 0).rgb;
    vec3 c01 = texelFetch(map, clamp(i + ivec2(0, 1), ivec2(0), hi), 0).rgb;
    vec3 c11 = texelFetch(map, clamp(i + ivec2(1, 1), ivec2(0), hi), 0).rgb;
    return mix(mix(c00, c10, a.x), mix(c01, c11, a.x), a.y);
#endif
}

void main() {
#ifdef SPHERE_IMPOSTOR
    vec3 v = normalize(v_world - eye);  // the ray through this pixel
    vec3 oc = eye - center;
    float b = dot(v, oc);
    float disc = b * b - (dot(oc, oc) - radius * radius);
    if (disc < 0.0) {
        discard;                    // the quad's corners, outside the outline
    }
    vec3 hit = eye + (-b - sqrt(disc)) * v;
    vec4 clip = view_projection * vec4(hit, 1.0);
    gl_FragDepth = 0.5 + 0.5 * clip.z / clip.w;  // (the default depth range)
    vec3 n = (hit - center) / radius;
#else
    vec3 n = normalize(v_normal);
#endif
    vec3 n_ts = vec3(0.0, 0.0, 1.0);  // the normal in tangent space
#ifdef NORMAL_MAP
    vec3 n_t = textureLod(normal_map, v_uv, normal_map_lod).xyz * 2.0 - 1.0;   // eq. 5.2
    n_ts = normalize(n_t);
    vec3 t = normalize(v_tangent);
    vec3 b = cross(n, t);
    n = normalize(mat3(t, b, n) * n_t);
#endif
#ifndef SPHERE_IMPOSTOR
    vec3 v = normalize(v_world - eye);
#endif
    vec3 light = vec3(1.0);
#ifdef LIGHT_MAP
    light = textureLod(light_map, v_uv2, light_map_lod).rgb;
#endif
#ifdef INM
    // Irradiance normal mapping: the basis at the tangent-space normal, weighted by the texel's
    // coefficients of the irradiance E; E / pi is what an irradiance map holds. PRT the same, its
    // coefficients relit from the transfer per texel (the coefficient map) or per vertex.
    float basis[BASIS_COUNT];
    basis_values(n_ts, basis);
    vec3 irradiance = vec3(0.0);
    for (int k = 0; k < inm_terms; k++) {
#ifdef PRT_VERTEX
        irradiance += basis[k] * v_prt[k];
#else
        irradiance += basis[k] * textureLod(coefficient_map, vec3(v_uv2, float(k)), coefficient_map_lod).rgb;
#endif
    }
    vec3 diffuse = irradiance / BASES_PI;
#elif defined(VOLUME)
    // An irradiance volume: the coefficients interpolated at the fragment's world position (grid points
    // on the box's corners, so texel centres map to them), SH bands 0-2 at the world normal.
#ifdef SPHERE_IMPOSTOR
    vec3 p = hit;
#else
    vec3 p = v_world;
#endif
    vec3 f = clamp((p - volume_low) / (volume_high - volume_low), 0.0, 1.0);
    vec3 uvw = (f * (volume_size - 1.0) + 0.5) / volume_size;
    float sh[9];
    sh[0] = 0.5 / sqrt(VOLUME_PI);
    float c1 = 0.5 * sqrt(3.0 / VOLUME_PI), c2 = 0.5 * sqrt(15.0 / VOLUME_PI), c3 = 0.25 * sqrt(5.0 / VOLUME_PI);
    sh[1] = c1 * n.y; sh[2] = c1 * n.z; sh[3] = c1 * n.x; sh[4] = c2 * n.x * n.y; sh[5] = c2 * n.y * n.z;
    sh[6] = c3 * (3.0 * n.z * n.z - 1.0); sh[7] = c2 * n.z * n.x; sh[8] = 0.5 * c2 * (n.x * n.x - n.y * n.y);
    vec3 irradiance = vec3(0.0);
    for (int k = 0; k < 9; k++) {
        irradiance += sh[k] * texture(volume[k], uvw).rgb;
    }
    vec3 diffuse = irradiance / VOLUME_PI;
#else
    // Alg. 5.4 line 9 uses the unperturbed n_w here, a typo for n (see render/shading.py).
    vec3 diffuse = lookup(irradiance_map, n) * light;
#endif
#ifdef GGX
    // Metallic-roughness with the split sum (Karis 2013): kd holds (1 - metallic) base_color.
    float n_dot_v = clamp(-dot(n, v), 0.0, 1.0);
    vec2 split = textureLod(brdf_lut, vec2(n_dot_v, roughness), 0.0).rg;
    vec3 prefiltered = textureLod(ggx_map, reflect(v, n), roughness * (ggx_levels - 1.0)).rgb;
    hdr = vec4(kd * diffuse + prefiltered * (f0 * split.x + split.y), 1.0);
#else
    vec3 specular = lookup(reflection_map, reflect(v, n));
    hdr = vec4(kd * diffuse + ks * specular, 1.0);
#endif
#ifdef DEBUG
#if defined(VOLUME)
#ifdef SPHERE_IMPOSTOR
    debug_normal = vec4(n, 0.0);
    debug_incident = vec4(hit, 0.0);     // the world point the volume was read at
#else
    debug_normal = vec4(n, 0.0);
    debug_incident = vec4(v_world, 0.0);
#endif
#elif defined(PRT_VERTEX)
    debug_normal = vec4(n_ts, 0.0);      // the normal and the world point (tests: coefficients linear in it)
    debug_incident = vec4(v_world, 0.0);
#elif defined(INM)
    debug_normal = vec4(n_ts, v_uv2.x);  // what the NumPy reference evaluates the light map with
    debug_incident = vec4(v, v_uv2.y);
#else
    debug_normal = vec4(n, light.r);
    debug_incident = vec4(v, 0.0);
#endif
#endif
}
