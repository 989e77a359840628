// Thesis Alg. 5.5: Reinhard's eq. 5.5 applied where the mask is set, over the LDR camera image. The
// average luminance of the masked pixels comes from the top of the HDR colour's mip chain: its rgb is
// the mean colour, its alpha (1 where an object was drawn, 0 elsewhere) the mask's coverage, so one
// chain serves both; line 6 of the algorithm samples the mask texture there, a typo for the colour
// texture. With LOG_AVERAGE, Reinhard's log-average instead: the mask's second channel holds
// log(delta + L_w) where an object was drawn, and its mip top over the coverage is their mean.
uniform sampler2D hdr;
uniform sampler2D mask;
uniform sampler2D background;       // the camera frame (display-referred, row 0 at the top)
uniform float key;                  // a
uniform float white;                // L_white
uniform float top_level;            // the 1 x 1 mip level (the targets are a power of two on each side,
                                    // the frame in their lower-left corner and zeros around it, so that
                                    // every level halves exactly and the top is the mean)

in vec2 uv;
out vec4 colour;

const vec3 LUMA = vec3(0.299, 0.587, 0.114);

void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    vec3 c_w = texelFetch(hdr, pixel, 0).rgb;
    float l_w = dot(c_w, LUMA);
    float m = texelFetch(mask, pixel, 0).r;
    vec4 mean = textureLod(hdr, vec2(0.5), top_level);
#ifdef LOG_AVERAGE
    float average = exp(textureLod(mask, vec2(0.5), top_level).g / max(mean.a, 1e-12));
#else
    float average = dot(mean.rgb, LUMA) / max(mean.a, 1e-12);
#endif
    float l = key * l_w / average;
    float l_d = l * (1.0 + l / (white * white)) / (1.0 + l);
    // Line 9 multiplies C_w by L_d; scaling the colour to luminance L_d is what it means.
    vec3 mapped = l_w > 0.0 ? c_w * (l_d / l_w) : vec3(0.0);
    vec3 camera = texture(background, vec2(uv.x, 1.0 - uv.y)).rgb;
    colour = vec4(m > 0.5 ? mapped : camera, 1.0);
}
