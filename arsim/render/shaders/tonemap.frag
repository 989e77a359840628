// Thesis Alg. 5.5: Reinhard's eq. 5.5 applied where the mask is set, drawn over the camera frame already
// in the output (step 4), on the objects' rectangle only. The HDR colour's alpha is the mask (the same
// fragments write 1 into both): one texel fetch per pixel instead of two, which llvmpipe makes the
// pass's main cost. The average luminance of the masked pixels
// comes from the top of the tile's HDR colour mip chain: its rgb is the mean colour, its alpha (1 where
// an object was drawn, 0 elsewhere) the mask's coverage, so one chain serves both; line 6 of the
// algorithm samples the mask texture there, a typo for the colour texture. With LOG_AVERAGE, Reinhard's
// log-average instead: the mask's second channel holds log(delta + L_w) where an object was drawn, and
// its mip top over the coverage is their mean.
uniform sampler2D hdr;              // the tile: the objects' rectangle in its lower-left corner
uniform sampler2D mask;
uniform ivec2 origin;               // the rectangle's corner in the frame (GL window coordinates)
uniform int frame_height;
uniform float key;                  // a
uniform float white;                // L_white
uniform int top_level;              // the 1 x 1 mip level (the tile is a power of two on each side, zeros
                                    // around the objects, so that every level halves exactly and the top
                                    // is the mean)

out vec4 colour;

const vec3 LUMA = vec3(0.299, 0.587, 0.114);

void main() {
    // The output's rows run from the image's top; the tile's, as the frame's in GL, from the bottom.
    ivec2 frame = ivec2(int(gl_FragCoord.x), frame_height - 1 - int(gl_FragCoord.y));
    vec4 pixel = texelFetch(hdr, frame - origin, 0);
    if (pixel.a < 0.5) {
        discard;                    // the camera image stays
    }
    vec3 c_w = pixel.rgb;
    float l_w = dot(c_w, LUMA);
    vec4 mean = texelFetch(hdr, ivec2(0), top_level);
#ifdef LOG_AVERAGE
    float average = exp(texelFetch(mask, ivec2(0), top_level).g / max(mean.a, 1e-12));
#else
    float average = dot(mean.rgb, LUMA) / max(mean.a, 1e-12);
#endif
    float l = key * l_w / average;
    float l_d = l * (1.0 + l / (white * white)) / (1.0 + l);
    // Line 9 multiplies C_w by L_d; scaling the colour to luminance L_d is what it means.
    colour = vec4(l_w > 0.0 ? c_w * (l_d / l_w) : vec3(0.0), 1.0);
}
