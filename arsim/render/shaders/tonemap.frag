// Thesis Alg. 5.5: Reinhard's eq. 5.5 applied where the mask is set, drawn over the camera frame already
// in the output (step 4), on the objects' rectangles only. The HDR colour's alpha is the mask: one
// texel fetch per pixel, which llvmpipe makes the pass's main cost. The average luminance of the masked pixels, l_average, comes from the vertex shader
// (rects.vert), which reads it from the top of the tile's average chain (average.frag); line 6 of the
// algorithm samples the mask texture's mip chain there, a typo for the colour's.
uniform sampler2D hdr;              // the tile: the objects' rectangle in its lower-left corner
uniform ivec2 origin;               // the rectangle's corner in the frame (GL window coordinates)
uniform int frame_height;
uniform float key;                  // a
uniform float white;                // L_white
flat in float l_average;

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
    float l = key * l_w / l_average;
    float l_d = l * (1.0 + l / (white * white)) / (1.0 + l);
    // Line 9 multiplies C_w by L_d; scaling the colour to luminance L_d is what it means.
    colour = vec4(l_w > 0.0 ? c_w * (l_d / l_w) : vec3(0.0), 1.0);
}
