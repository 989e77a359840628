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
#ifdef TORUS_IMPOSTOR
uniform mat4 object_from_world;     // the inverse of the model matrix
uniform mat3 normal_matrix;
uniform vec2 torus_radii;           // major, minor (object units): resting on y = 0 about the y axis
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

#ifdef TORUS_IMPOSTOR
float cube_root(float x) {
    return sign(x) * pow(abs(x), 1.0 / 3.0);
}

// The torus along the ray from the eye in world direction v: the nearest hit in front of the eye, its
// world point, normal and tangent (along increasing u) and its (u, v) as content.torus_surface has them;
// false where the ray misses. In object space, lengths in major radii and s measured from the ray's
// point nearest the torus's centre (coefficients of order 1), the quartic
// (|p|^2 + 1 - r^2)^2 = 4 (p.x^2 + p.z^2) reads s^4 + P s^2 + Q s + S = 0; Ferrari's method splits it
// into two quadratics with the largest root of its resolvent cubic, and two Newton steps polish the root.
bool torus_hit(vec3 v, out vec3 hit, out vec3 n, out vec3 tangent, out vec2 uv) {
    float major = torus_radii.x, r = torus_radii.y / major;
    vec3 o = ((object_from_world * vec4(eye, 1.0)).xyz - vec3(0.0, torus_radii.y, 0.0)) / major;
    vec3 d = mat3(object_from_world) * v;
    float stretch = length(d);      // object length per world length
    d /= stretch;
    float B = dot(o, d);
    vec3 e = o - B * d;             // the ray's point nearest the centre: p = e + s d, s = t + B
    float G = dot(e, e) + 1.0 - r * r;
    float a = d.x * d.x + d.z * d.z, b = e.x * d.x + e.z * d.z, c = e.x * e.x + e.z * e.z;
    float P = 2.0 * G - 4.0 * a, Q = -8.0 * b, S = G * G - 4.0 * c;
    // The resolvent y^3 - P/2 y^2 - S y + (P S / 2 - Q^2 / 8) = 0, depressed (y = z + P / 6): its largest root.
    float a2 = -0.5 * P, a1 = -S, a0 = 0.5 * P * S - 0.125 * Q * Q;
    float p3 = (a1 - a2 * a2 / 3.0) / 3.0, q2 = 0.5 * (2.0 * a2 * a2 * a2 / 27.0 - a2 * a1 / 3.0 + a0);
    float disc = q2 * q2 + p3 * p3 * p3;
    float z;
    if (disc > 0.0) {
        // (Cardano's two cube roots, the second from the first: the sum of cube roots would cancel)
        float u = cube_root(-q2 - (q2 >= 0.0 ? 1.0 : -1.0) * sqrt(disc));
        z = u - p3 / u;
    } else {
        float m = sqrt(max(-p3, 0.0));
        z = 2.0 * m * cos(acos(clamp(-q2 / max(m * m * m, 1e-30), -1.0, 1.0)) / 3.0);
    }
    float y = z - a2 / 3.0;
    for (int i = 0; i < 2; i++) {   // (polished: the cube root and the cosine are llvmpipe's approximations)
        float g = ((y + a2) * y + a1) * y + a0, dg = (3.0 * y + 2.0 * a2) * y + a1;
        y -= abs(dg) > 1e-12 ? g / dg : 0.0;
    }
    float w = sqrt(max(2.0 * y - P, 0.0));
    // (s^2 + y)^2 = (w s - h)^2 with 2 w h = Q and h^2 = y^2 - S: s^2 - w s + y + h = 0 and s^2 + w s + y - h = 0.
    // h from whichever of the two is the better conditioned: w = sqrt(2 y - P) cancels where it is small.
    float h2 = y * y - S;
    float h = h2 > w * w || w < 1e-12 ? sign(Q) * sqrt(max(h2, 0.0)) : Q / (2.0 * w);
    // The real roots in front of the eye, nearest first, each polished by two Newton steps, until one lies on
    // the torus: a ray that grazes it before it hits can give a pair of roots that rounding made real.
    float k1 = w * w - 4.0 * (y + h), k2 = w * w - 4.0 * (y - h);
    float q1 = k1 >= 0.0 ? sqrt(k1) : 0.0, q2r = k2 >= 0.0 ? sqrt(k2) : 0.0;
    vec4 roots = vec4(0.5 * (w - q1), 0.5 * (w + q1), 0.5 * (-w - q2r), 0.5 * (-w + q2r));
    roots = mix(vec4(1e30), roots, vec4(bvec4(k1 >= 0.0, k1 >= 0.0, k2 >= 0.0, k2 >= 0.0)));
    float last = B, s;
    vec3 p;
    for (int pass = 0; pass < 4; pass++) {
        vec4 ahead = mix(vec4(1e30), roots, greaterThan(roots, vec4(last)));
        float root = min(min(ahead.x, ahead.y), min(ahead.z, ahead.w));
        if (root > 1e29) {
            return false;
        }
        last = root;
        s = root;
        for (int i = 0; i < 2; i++) {
            float s2 = s * s;
            float f = (s2 + G) * (s2 + G) - 4.0 * (c + 2.0 * b * s + a * s2);
            float df = 4.0 * s * (s2 + G) - 8.0 * (b + a * s);
            s -= abs(df) > 1e-12 ? f / df : 0.0;
        }
        p = e + s * d;
        if (s > B && abs(length(vec2(length(p.xz) - 1.0, p.y)) - r) < 1e-3 * r) {
            break;
        }
        if (pass == 3) {
            return false;
        }
    }
    hit = eye + (s - B) * major / stretch * v;
    vec3 ring = normalize(vec3(p.x, 0.0, p.z));
    vec3 normal = normalize(p - ring);
    n = normalize(normal_matrix * normal);
    tangent = normalize(normal_matrix * vec3(ring.z, 0.0, -ring.x));
    uv = fract(vec2(atan(ring.x, ring.z), atan(normal.y, dot(normal, ring))) / (2.0 * PI));
    return true;
}
#endif

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
#elif defined(TORUS_IMPOSTOR)
    vec3 v = normalize(v_world - eye);  // the ray through this pixel
    vec3 hit, n, tangent;
    vec2 uv;
    if (!torus_hit(v, hit, n, tangent, uv)) {
        discard;                    // between the proxy's faces and the torus
    }
    if (length(hit - eye) < (1.0 - 1e-5) * length(v_world - eye)) {
        discard;                    // a face of the proxy behind the hit: the one in front shades it
    }
    vec4 clip = view_projection * vec4(hit, 1.0);
    gl_FragDepth = 0.5 + 0.5 * clip.z / clip.w;
    vec2 uv2 = uv;                  // (both UV sets are (u, v): content.torus)
#else
    vec3 n = normalize(v_normal);
#endif
#if !defined(SPHERE_IMPOSTOR) && !defined(TORUS_IMPOSTOR)
    vec2 uv = v_uv, uv2 = v_uv2;
    vec3 tangent = v_tangent;
#endif
    vec3 n_ts = vec3(0.0, 0.0, 1.0);  // the normal in tangent space
#ifdef NORMAL_MAP
    vec3 n_t = textureLod(normal_map, uv, normal_map_lod).xyz * 2.0 - 1.0;   // eq. 5.2
    n_ts = normalize(n_t);
    vec3 t = normalize(tangent);
    vec3 b = cross(n, t);
    n = normalize(mat3(t, b, n) * n_t);
#endif
#if !defined(SPHERE_IMPOSTOR) && !defined(TORUS_IMPOSTOR)
    vec3 v = normalize(v_world - eye);
#endif
    vec3 light = vec3(1.0);
#ifdef LIGHT_MAP
    light = textureLod(light_map, uv2, light_map_lod).rgb;
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
        irradiance += basis[k] * textureLod(coefficient_map, vec3(uv2, float(k)), coefficient_map_lod).rgb;
#endif
    }
    vec3 diffuse = irradiance / BASES_PI;
#elif defined(VOLUME)
    // An irradiance volume: the coefficients interpolated at the fragment's world position (grid points
    // on the box's corners, so texel centres map to them), SH bands 0-2 at the world normal.
#if defined(SPHERE_IMPOSTOR) || defined(TORUS_IMPOSTOR)
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
#if defined(SPHERE_IMPOSTOR) || defined(TORUS_IMPOSTOR)
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
    debug_normal = vec4(n_ts, uv2.x);    // what the NumPy reference evaluates the light map with
    debug_incident = vec4(v, uv2.y);
#else
    debug_normal = vec4(n, light.r);
    debug_incident = vec4(v, 0.0);
#endif
#endif
}
