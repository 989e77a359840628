// The tone mapper's average, step two: the average target's texels (average.frag's blocks) summed over the box
// that holds the objects' blocks, zeros elsewhere: (the luminance's or its log's sum, the coverage's), whose
// ratio is the masked pixels' mean. Row by row and then the rows' sums: float32's rounding grows with a row's
// length and the rows' count, not their product. Shared by the tone mapper's vertex shader (rects.vert), which
// sums once per corner instead of a pass of its own (on llvmpipe a pass into a 1 x 1 target cost 0.11-0.14 ms a
// frame, whatever the box's size), and by average_sum.frag, which reads the same sums back for tests.
vec2 block_sums(sampler2D blocks, ivec4 box) {  // box: x0, y0, x1, y1 (x1, y1 exclusive), in the target's texels
    vec2 sum = vec2(0.0);
    for (int y = box.y; y < box.w; y++) {
        vec2 row = vec2(0.0);
        for (int x = box.x; x < box.z; x++) {
            row += texelFetch(blocks, ivec2(x, y), 0).rg;
        }
        sum += row;
    }
    return sum;
}
