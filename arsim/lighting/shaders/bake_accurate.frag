// Thesis Alg. 4.1/4.2: the accurate maps, MAPS of them at once (one colour attachment each), for the
// texels of one tile. Per output texel d: M_s(d) = sum_i L_i W_i f_i / sum_i W_i f_i with
// f_i = max(0, d.w_i)^s over the input texels i of the disk (W_i their solid angles); with BOUNDS, f_i
// below the threshold is dropped (the bounds optimisation: the texels to visit come from a candidate list
// the CPU builds for the tile, the cone of the widest lobe). The sums are compensated (Kahan, `precise`
// so the compiler keeps them): float32 over 200 000 terms would otherwise lose up to 1e-3. A pass sums a
// range of the input texels (or candidates) and its sums are added into the tile's by blending, so that
// a bake can spread one tile over frames; bake_resolve.frag then divides.
layout(std430, binding = 0) readonly buffer Probe { vec4 probe[]; };      // per input texel: w_i, W_i
layout(std430, binding = 1) readonly buffer Radiance { vec4 radiance[]; }; // per input texel: L_i W_i
layout(std430, binding = 2) readonly buffer Candidates { int candidates[]; };
uniform sampler2D directions;       // output texel directions (xyz; w = 1 inside the disk, 0 outside)
uniform int first;                  // the range of input texels (or candidates) this pass sums
uniform int count;
uniform float exponents[MAPS];
uniform float threshold;

layout(location = 0) out vec4 sums[MAPS];  // (sum_i f_i L_i W_i, sum_i f_i W_i), added to the tile's

void main() {
    vec4 d = texelFetch(directions, ivec2(gl_FragCoord.xy), 0);
    if (d.w == 0.0) {
        for (int k = 0; k < MAPS; k++) sums[k] = vec4(0.0);
        return;
    }
    precise vec4 sum[MAPS];
    precise vec4 carry[MAPS];
    for (int k = 0; k < MAPS; k++) {
        sum[k] = vec4(0.0);
        carry[k] = vec4(0.0);
    }
    for (int j = first; j < first + count; j++) {
#ifdef BOUNDS
        int i = candidates[j];
#else
        int i = j;
#endif
        vec4 w = probe[i];
        float c = dot(d.xyz, w.xyz);
        if (c <= 0.0) continue;
        vec4 term = vec4(radiance[i].rgb, w.w);
        for (int k = 0; k < MAPS; k++) {
            float f = exponents[k] == 1.0 ? c : pow(c, exponents[k]);
#ifdef BOUNDS
            if (f < threshold) continue;
#endif
            precise vec4 y = f * term - carry[k];
            precise vec4 t = sum[k] + y;
            carry[k] = (t - sum[k]) - y;
            sum[k] = t;
        }
    }
    for (int k = 0; k < MAPS; k++) {
        sums[k] = sum[k];
    }
}
