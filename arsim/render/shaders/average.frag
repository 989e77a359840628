// The tone mapper's average, step one: each fragment of the average target sums a block of BLOCK x BLOCK
// texels of the tile's HDR colour (the objects' rectangles only, grown to whole blocks; the tile is
// zero elsewhere), writing (the block's mean luminance or, with LOG_AVERAGE, the mean of log(delta +
// L_w) over its drawn texels, the block's coverage). The target's mip chain then gives the means over
// the tile: the masked pixels' average is its top's first channel over its second, the same value as a
// mip chain over the whole tile (renderer.py). Without LOG_AVERAGE, bilinear fetches at the corners
// shared by 2 x 2 texels read the block a quarter of the fetches (weights of exactly 1/2: exact in float
// and in a GPU's 8-bit weights); the log is not linear, so the log-average reads the texels one by one.
uniform sampler2D hdr;

out vec4 average;

const vec3 LUMA = vec3(0.299, 0.587, 0.114);
const float LOG_DELTA = 1e-4;       // Reinhard's delta in the log-average (render/shading.py)

void main() {
    ivec2 corner = ivec2(gl_FragCoord.xy) * BLOCK;
    float value = 0.0, coverage = 0.0;
#ifdef LOG_AVERAGE
    for (int j = 0; j < BLOCK; j++) {
        for (int i = 0; i < BLOCK; i++) {
            vec4 c = texelFetch(hdr, corner + ivec2(i, j), 0);
            value += c.a > 0.5 ? log(LOG_DELTA + dot(c.rgb, LUMA)) : 0.0;
            coverage += c.a;
        }
    }
#else
    vec2 size = vec2(textureSize(hdr, 0));
    vec4 sum = vec4(0.0);
    for (int j = 1; j < BLOCK; j += 2) {
        for (int i = 1; i < BLOCK; i += 2) {
            sum += textureLod(hdr, (vec2(corner) + vec2(i, j)) / size, 0.0);
        }
    }
    value = dot(sum.rgb, LUMA) * 4.0;
    coverage = sum.a * 4.0;
#endif
    average = vec4(value, coverage, 0.0, 0.0) / float(BLOCK * BLOCK);
}
