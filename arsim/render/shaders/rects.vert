// Rectangles given by their corners in the frame's GL window pixels (from the bottom), drawn into the
// output, whose rows run from the image's top: y turns over (the tone mapping's objects' rectangles).
// With AVERAGE (the tone mapping), the masked pixels' average luminance from the sums of average.frag's blocks
// (average_sum.glsl), taken here once per corner rather than once per pixel:
// the tile's luminance over its coverage (1 where an object was drawn, 0 elsewhere), or with LOG_AVERAGE
// the exponential of the mean of log(delta + L_w) over the drawn pixels.
uniform vec2 frame_size;
in vec2 in_corner;
#ifdef AVERAGE
uniform sampler2D blocks;           // average.frag's target: per block (the luminance's or its log's mean, coverage)
uniform ivec4 box;                  // the blocks' box in it
flat out float l_average;
#endif

void main() {
#ifdef AVERAGE
    vec2 mean = block_sums(blocks, box);  // (luminance or its log, coverage)
#ifdef LOG_AVERAGE
    l_average = exp(mean.r / max(mean.g, 1e-12));
#else
    l_average = mean.r / max(mean.g, 1e-12);
#endif
#endif
    vec2 ndc = vec2(in_corner.x, frame_size.y - in_corner.y) / frame_size * 2.0 - 1.0;
    gl_Position = vec4(ndc, 0.0, 1.0);
}
