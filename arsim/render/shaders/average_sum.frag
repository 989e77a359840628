// The tone mapper's average, step two: one fragment sums the average target's texels (average.frag's
// blocks) over the box that holds the objects' blocks, zeros elsewhere: (the luminance's or its log's sum,
// the coverage's), whose ratio is the masked pixels' mean. One pass instead of the target's mip chain,
// which llvmpipe builds with a blit per level at 0.5-0.7 ms a frame whatever the target's size. Row by row
// and then the rows' sums: float32's rounding grows with a row's length and the rows' count, not their product.
uniform sampler2D blocks;
uniform ivec4 box;                  // x0, y0, x1, y1 (x1, y1 exclusive), in the target's texels

out vec4 total;

void main() {
    vec2 sum = vec2(0.0);
    for (int y = box.y; y < box.w; y++) {
        vec2 row = vec2(0.0);
        for (int x = box.x; x < box.z; x++) {
            row += texelFetch(blocks, ivec2(x, y), 0).rg;
        }
        sum += row;
    }
    total = vec4(sum, 0.0, 0.0);
}
