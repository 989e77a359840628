// Thesis Alg. 4.7: MAPS maps at once from SH coefficients, for the texels of one tile:
// M_s(d) = sum_l kappa_l(s) sum_m c_lm Y_lm(d) (eq. 2.31, 2.33), evaluated directly at each texel's
// direction. The SH frame is sh.py's (pole +z, phi = atan2(d_y, -d_x)), and Y_lm come from the same
// orthonormalised recurrences (no factorials), here in float32.
uniform sampler2D directions;       // output texel directions (xyz; w = 1 inside the disk, 0 outside)
uniform sampler2D coefficients;     // the coefficient texture: c_lm (rgb) at index l(l+1)+m, rows of 1024
uniform sampler2D kappas;           // kappa_l(s_k) (r) at texel (l, k): the Phong lobe's zonal factors
uniform int order;                  // bands 0 .. order-1

layout(location = 0) out vec4 maps[MAPS];

const float PI = 3.14159265358979;

vec4 coefficient(int index) {
    return texelFetch(coefficients, ivec2(index % 1024, index / 1024), 0);
}

void main() {
    vec4 d = texelFetch(directions, ivec2(gl_FragCoord.xy), 0);
    vec3 sum[MAPS];
    for (int k = 0; k < MAPS; k++) sum[k] = vec3(0.0);
    if (d.w != 0.0) {
        float x = d.z;                              // cos(theta)
        float sin_theta = length(d.xy);
        float phi = atan(d.y, -d.x);
        float p_mm = 1.0 / sqrt(4.0 * PI);
        for (int m = 0; m < order; m++) {
            if (m > 0) {
                p_mm *= -sqrt(float(2 * m + 1) / float(2 * m)) * sin_theta;
            }
            float c = cos(float(m) * phi), s = sin(float(m) * phi);
            float p2 = 0.0, p1 = 0.0, p = p_mm;
            for (int l = m; l < order; l++) {
                if (l == m + 1) {
                    p = sqrt(float(2 * m + 3)) * x * p_mm;
                } else if (l > m + 1) {
                    float a = sqrt(float(4 * l * l - 1) / float(l * l - m * m));
                    float ab = a * sqrt(float((l - 1) * (l - 1) - m * m) / float(4 * (l - 1) * (l - 1) - 1));
                    p = a * x * p1 - ab * p2;
                }
                vec3 basis = coefficient(l * (l + 1) + m).rgb * p;
                if (m > 0) {
                    vec3 minus = coefficient(l * (l + 1) - m).rgb * p;
                    basis = sqrt(2.0) * (basis * c + minus * s);
                }
                for (int k = 0; k < MAPS; k++) {
                    sum[k] += texelFetch(kappas, ivec2(l, k), 0).r * basis;
                }
                p2 = p1;
                p1 = p;
            }
        }
    }
    for (int k = 0; k < MAPS; k++) maps[k] = vec4(sum[k], 1.0);
}
