// Thesis Alg. 4.1/4.2: the accurate maps, MAPS of them at once (one colour attachment each), for the
// texels of one tile. Per output texel d: M_s(d) = sum_i L_i W_i f_i / sum_i W_i f_i with
// f_i = max(0, d.w_i)^s over the input texels i of the disk (W_i their solid angles); with BOUNDS, f_i
// below the threshold is dropped (the bounds optimisation). The input texels visited come as spans of
// consecutive indices that the CPU finds for the tile: those within 90 degrees of any of its texels
// (all others give f = 0), or with BOUNDS within the cone of the widest kept lobe. Spans from a uniform
// block keep every index the same across the fragments, so each input is one load for all of them.
// The sums are compensated (Kahan, `precise` so the compiler keeps them): float32 over 200 000 terms
// would otherwise lose up to 1e-3. The terms of each run of FOLD_TERMS indices are added plainly and the
// run's sum then into the compensated one: the same errors against NumPy as compensating every term
// (8.95e-5 at 128²); on llvmpipe a 32² tile over 1 024 input texels (the loop's draws) 1.6 times as
// fast, a whole 16² tile about 1.2 times. The runs are a loop of their own: a fold every
// FOLD_TERMS-th term tested inside the term loop cost as much as compensating each. A draw sums some of
// the visited texels and its sums are added into the tile's by blending, so that a bake can spread one
// tile over frames; bake_resolve.frag then divides.
layout(std430, binding = 0) readonly buffer Probe { vec4 probe[]; };      // per input texel: w_i, W_i
layout(std430, binding = 1) readonly buffer Radiance { vec4 radiance[]; }; // per input texel: L_i W_i
layout(std140) uniform Spans { ivec4 spans[MAX_SPANS / 2]; };  // two [start, end) of input indices each
uniform int span_count;
uniform sampler2D directions;       // output texel directions (xyz; w = 1 inside the disk, 0 outside)
uniform float exponents[MAPS];
uniform float threshold;

layout(location = 0) out vec4 sums[MAPS];  // (sum_i f_i L_i W_i, sum_i f_i W_i), added to the tile's

// Adds each part (a plain float32 sum of up to FOLD_TERMS terms) into its compensated sum, and clears it.
void fold(inout precise vec4 sum[MAPS], inout precise vec4 carry[MAPS], inout vec4 part[MAPS]) {
    for (int k = 0; k < MAPS; k++) {
        if (part[k] == vec4(0.0)) continue;
        precise vec4 y = part[k] - carry[k];
        precise vec4 t = sum[k] + y;
        carry[k] = (t - sum[k]) - y;
        sum[k] = t;
        part[k] = vec4(0.0);
    }
}

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
    vec4 part[MAPS];
    for (int k = 0; k < MAPS; k++) part[k] = vec4(0.0);
    // A run's part is folded when the next run begins in another block of FOLD_TERMS indices (and the
    // parts with no term are not: folding a zero is no exact no-op). So the parts hold the same terms
    // whatever spans a tile has (they differ from tile to tile): a texel's sum is the same, bit for bit,
    // in whatever tile it is baked.
    int block = -1;
    for (int r = 0; r < span_count; r++) {
        ivec4 pair = spans[r / 2];
        ivec2 span = (r & 1) == 0 ? pair.xy : pair.zw;
        for (int i = span.x; i < span.y;) {
            if (i / FOLD_TERMS != block) {
                fold(sum, carry, part);
                block = i / FOLD_TERMS;
            }
            int run_end = min((block + 1) * FOLD_TERMS, span.y);
            for (; i < run_end; i++) {
                vec4 w = probe[i];
                float c = dot(d.xyz, w.xyz);
                if (c <= 0.0) continue;
                vec4 term = vec4(radiance[i].rgb, w.w);
                for (int k = 0; k < MAPS; k++) {
                    float f = exponents[k] == 1.0 ? c : pow(c, exponents[k]);
#ifdef BOUNDS
                    if (f < threshold) continue;
#endif
                    part[k] += f * term;
                }
            }
        }
    }
    fold(sum, carry, part);
    for (int k = 0; k < MAPS; k++) {
        sums[k] = sum[k];
    }
}
