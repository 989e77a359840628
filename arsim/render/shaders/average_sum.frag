// The tone mapper's average as its vertex shader sums it (average_sum.glsl), into a 1 x 1 target: what
// Renderer.mip_average reads back (tests), not a pass of the frame.
uniform sampler2D blocks;
uniform ivec4 box;

out vec4 total;

void main() {
    total = vec4(block_sums(blocks, box), 0.0, 0.0);
}
