// Angle-map coordinates (README: Conventions), shared by every shader that looks up an environment or a map.

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

