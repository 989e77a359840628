// The bases of irradiance normal mapping in GLSL, the same functions as arsim/lighting/bases/functions.py
// (its docstring lists the spec's typos and what is done instead), in tangent space (z the surface
// normal). Define one of BASIS_SH, BASIS_HL2, BASIS_H, BASIS_MODH, BASIS_HSH, BASIS_MAKHOTKIN,
// BASIS_ZERNIKE, BASIS_SEP and BASIS_COUNT; basis_values(n) fills the first BASIS_COUNT functions at the unit n.
// BASIS_SEP: PRT's separable basis (arsim/lighting/prt.py), a table over the normal's orthographic
// projection, read bilinearly here in float as prt._bilinear reads it.

const float BASES_PI = 3.14159265358979;
#if defined(BASIS_SEP)
uniform sampler2D sep_basis;        // 64 x 64, the U columns in RGBA, row 0 at y = -1

vec4 sep_lookup(vec2 xy) {
    ivec2 size = textureSize(sep_basis, 0);
    vec2 p = clamp((xy + 1.0) * 0.5 * vec2(size) - 0.5, vec2(0.0), vec2(size - 1));
    ivec2 i = min(ivec2(floor(p)), size - 2);
    vec2 a = p - vec2(i);
    vec4 c00 = texelFetch(sep_basis, i, 0), c10 = texelFetch(sep_basis, i + ivec2(1, 0), 0);
    vec4 c01 = texelFetch(sep_basis, i + ivec2(0, 1), 0), c11 = texelFetch(sep_basis, i + ivec2(1, 1), 0);
    return mix(mix(c00, c10, a.x), mix(c01, c11, a.x), a.y);
}
#endif

void basis_values(vec3 n, out float b[BASIS_COUNT]) {
    float x = n.x, y = n.y, z = n.z;
    float f[9];
    for (int k = 0; k < 9; k++) f[k] = 0.0;
#if defined(BASIS_SH)
    float c0 = 0.5 / sqrt(BASES_PI), c1 = 0.5 * sqrt(3.0 / BASES_PI), c2 = 0.5 * sqrt(15.0 / BASES_PI);
    float c3 = 0.25 * sqrt(5.0 / BASES_PI);
    f[0] = c0; f[1] = c1 * y; f[2] = c1 * z; f[3] = c1 * x;
    f[4] = c2 * x * y; f[5] = c2 * y * z; f[6] = c3 * (3.0 * z * z - 1.0); f[7] = c2 * z * x;
    f[8] = 0.5 * c2 * (x * x - y * y);
#elif defined(BASIS_HL2)
    float a = sqrt(3.0 / (2.0 * BASES_PI));
    f[0] = a * dot(n, vec3(-1.0 / sqrt(6.0), -1.0 / sqrt(2.0), 1.0 / sqrt(3.0)));
    f[1] = a * dot(n, vec3(-1.0 / sqrt(6.0), 1.0 / sqrt(2.0), 1.0 / sqrt(3.0)));
    f[2] = a * dot(n, vec3(sqrt(2.0 / 3.0), 0.0, 1.0 / sqrt(3.0)));
#elif defined(BASIS_H) || defined(BASIS_MODH)
    float a = sqrt(3.0 / (2.0 * BASES_PI)), c = sqrt(15.0 / (2.0 * BASES_PI));
    f[0] = 1.0 / sqrt(2.0 * BASES_PI); f[1] = a * y; f[3] = a * x; f[4] = c * x * y; f[5] = 0.5 * c * (x * x - y * y);
#if defined(BASIS_MODH)
    f[2] = a * (1.0 - z);   // eq. 1.58: with n = (0, 0, 1) only f[0] remains, the light map
#else
    f[2] = a * (2.0 * z - 1.0);
#endif
#elif defined(BASIS_HSH)
    // Shifted SH: K~ {sqrt2 cos(m phi), sqrt2 sin(-m phi), 1} P_l^|m|(2z - 1), no Condon-Shortley phase.
    float t = 2.0 * clamp(z, 0.0, 1.0) - 1.0;
    float s = sqrt(max(1.0 - t * t, 0.0));
    float rho = length(n.xy);
    float cp = rho > 0.0 ? x / rho : 1.0, sp = rho > 0.0 ? y / rho : 0.0;   // cos, sin of phi
    float c2p = cp * cp - sp * sp, s2p = 2.0 * sp * cp;
    float r2 = sqrt(2.0);
    f[0] = sqrt(1.0 / (2.0 * BASES_PI));
    float k11 = sqrt(3.0 / (4.0 * BASES_PI));
    f[1] = k11 * r2 * sp * s; f[2] = sqrt(3.0 / (2.0 * BASES_PI)) * t; f[3] = k11 * r2 * cp * s;
    float k22 = sqrt(5.0 / (48.0 * BASES_PI)), k21 = sqrt(5.0 / (12.0 * BASES_PI));
    f[4] = k22 * r2 * s2p * 3.0 * (1.0 - t * t); f[5] = k21 * r2 * sp * 3.0 * t * s;
    f[6] = sqrt(5.0 / (2.0 * BASES_PI)) * 0.5 * (3.0 * t * t - 1.0);
    f[7] = k21 * r2 * cp * 3.0 * t * s; f[8] = k22 * r2 * c2p * 3.0 * (1.0 - t * t);
#elif defined(BASIS_MAKHOTKIN)
    float zc = clamp(z, 0.0, 1.0), r = sqrt(zc), w = 1.0 / sqrt(1.0 + zc);
    f[0] = r / sqrt(BASES_PI);
    f[1] = 2.0 * sqrt(3.0 / BASES_PI) * x * zc * w;
    f[2] = r * (6.0 * zc - 4.0) / sqrt(2.0 * BASES_PI);
    f[3] = 2.0 * sqrt(3.0 / BASES_PI) * y * zc * w;
    f[4] = 2.0 * sqrt(15.0 / BASES_PI) * zc * r * (x * x - y * y) / (1.0 + zc);
    f[5] = sqrt(3.0 / BASES_PI) * x * zc * (10.0 * zc - 6.0) * w;
    f[6] = sqrt(3.0 / BASES_PI) * r * (1.0 + 8.0 * (zc - 1.0) + 10.0 * (zc - 1.0) * (zc - 1.0));
    f[7] = sqrt(3.0 / BASES_PI) * y * zc * (10.0 * zc - 6.0) * w;
    f[8] = 4.0 * sqrt(15.0 / BASES_PI) * x * y * zc * r / (1.0 + zc);
#elif defined(BASIS_SEP)
    vec4 u = sep_lookup(n.xy);
    f[0] = u.x; f[1] = u.y; f[2] = u.z; f[3] = u.w;
#elif defined(BASIS_ZERNIKE)
    float w = 1.0 / (1.0 + z);
    f[0] = 1.0 / sqrt(2.0 * BASES_PI); f[1] = -sqrt(2.0 / BASES_PI) * y * sqrt(w); f[2] = sqrt(2.0 / BASES_PI) * x * sqrt(w);
    f[3] = -2.0 * sqrt(3.0 / BASES_PI) * x * y * w; f[4] = sqrt(3.0 / (2.0 * BASES_PI)) * (1.0 - 2.0 * z);
    f[5] = sqrt(3.0 / BASES_PI) * (x * x - y * y) * w;
#endif
    for (int k = 0; k < BASIS_COUNT; k++) b[k] = f[k];
}
