// An 8-bit camera frame: the environment's radiance through the sensor model of camera.expose
// (vignetting, shot and read noise, analog gain, clipping, response curve, quantisation).
// camera.expose with camera.pixel_normals is its NumPy reference; the float32 operations are the
// same and in the same order. A compute shader: one invocation per pixel, rows of 64 (llvmpipe runs
// it about a tenth faster than the same work as a fragment shader). The codes go to a buffer, a pixel's
// RGBA in one word: llvmpipe's stores to an RGBA8UI image took about 0.75 ms more of CPU a 640 x 480 frame.

layout(local_size_x = 64, local_size_y = 1) in;
layout(std430, binding = 0) writeonly buffer Codes {
    uint codes[];   // the frame, top row first, row-major: red in the low byte, then green, blue, 255
};

uniform float electrons_per_radiance;
uniform float read_noise_var;       // read noise squared, electrons^2
uniform float gain;                 // iso / base_iso / full_well: electrons to relative exposure
uniform uint noise_key;             // camera.noise_key(seed, stream, frame)
uniform int width;
uniform int height;
#ifndef ONE_STEP
uniform float thresholds[255];      // code c covers [t[c-1], t[c]) (float32, rounded up)
#endif
// Codes from bins even in sqrt(x) (ResponseCurve.guess_table and step_table, four codes per word).
const uint GUESS_BINS = 1024u;
uniform uint guess_table[GUESS_BINS / 4u];
#ifdef ONE_STEP
// The curve holds at most one threshold per bin: the bin's lowest code, plus one where x reaches that threshold
// (+inf where the bin holds none). Two lookups a channel instead of a guess and two settling steps (the same codes).
uniform float step_table[GUESS_BINS];
#endif

uvec4 pcg_hash(uvec4 v) {  // camera.pcg_hash
    uvec4 state = v * 747796405u + 2891336453u;
    uvec4 word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// The number of thresholds <= x, exactly as ResponseCurve.encode counts them. Without ONE_STEP: from the guess
// (the code at the centre of x's bin), at most SETTLE_STEPS (defined by the host: guess_table's bound) down, then
// up. Loops with a fixed count, as llvmpipe runs data-dependent loops far slower.
uint encode(float x) {
    uint bin = min(uint(sqrt(x) * float(GUESS_BINS)), GUESS_BINS - 1u);
    uint c = (guess_table[bin >> 2u] >> (8u * (bin & 3u))) & 255u;
#ifdef ONE_STEP
    return c + uint(x >= step_table[bin]);
#else
    for (int i = 0; i < SETTLE_STEPS; i++) {
        if (c > 0u && x < thresholds[c - 1u]) c--;
    }
    for (int i = 0; i < SETTLE_STEPS; i++) {
        if (c < 255u && x >= thresholds[c]) c++;
    }
    return c;
#endif
}

void main() {
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
    if (pixel.x >= width || pixel.y >= height) return;  // the last group of a row may stick out
    uint p = uint(pixel.y) * uint(width) + uint(pixel.x);  // pixel index, row-major
    vec4 ray = texelFetch(rays, pixel, 0);  // w: the vignetting (one fetch for both)
    vec3 electrons = max(radiance_along(pixel, camera_to_world * ray.xyz) * electrons_per_radiance * ray.w, 0.0);
    // Four hashed uniforms in (0, 1] per pixel (exact in float32), two Box-Muller pairs: cosine and
    // sine of the first for red and green, the cosine of the second for blue.
    uvec4 h = pcg_hash(4u * p + uvec4(0u, 1u, 2u, 3u) + noise_key);
    vec4 u = vec4((h >> 8u) + 1u) * (1.0 / 16777216.0);
    vec2 radius = sqrt(-2.0 * log(u.xz));
    vec3 normal = vec3(radius.x * cos(2.0 * PI * u.y), radius.x * sin(2.0 * PI * u.y), radius.y * cos(2.0 * PI * u.w));
    vec3 e = electrons + normal * sqrt(electrons + read_noise_var);
    vec3 signal = clamp(e * gain, 0.0, 1.0);
    codes[p] = encode(signal.r) | (encode(signal.g) << 8u) | (encode(signal.b) << 16u) | (255u << 24u);
}
