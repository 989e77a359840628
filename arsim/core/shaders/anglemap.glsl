// Angle-map coordinates (README: Conventions), shared by every shader that looks up an environment or a map.

const float PI = 3.14159265358979;

// Thesis Alg. 2.2 (angle-map coordinates of a direction) with its guard: the azimuth is undefined
// at -z, which maps to the rim point (0.5, 1); +z maps to the centre.
vec2 anglemap_st(vec3 d) {
    float b = length(d.xy);
    if (b <= 0.0) {
        return d.z < 0.0 ? vec2(0.5, 1.0) : vec2(0.5, 0.5);
    }
    // a = acos(d.z / |d|): Abramowitz and Stegun 4.4.46 (within 2e-8 rad), cheaper on llvmpipe than atan
    float z = d.z * inversesqrt(dot(d, d)), x = abs(z);
    float a = -0.0012624911;
    a = a * x + 0.0066700901;
    a = a * x - 0.0170881256;
    a = a * x + 0.0308918810;
    a = a * x - 0.0501743046;
    a = a * x + 0.0889789874;
    a = a * x - 0.2145988016;
    a = a * x + 1.5707963050;
    a *= sqrt(max(1.0 - x, 0.0));
    a = z < 0.0 ? PI - a : a;
    return vec2(0.5) + 0.5 * (d.xy / b) * (a / PI);
}

