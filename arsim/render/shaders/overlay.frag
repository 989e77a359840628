// Step 7: the overlay's text (renderer.overlay_coverage: its coverage, one channel), white on a box at
// BOX_ALPHA / 255 opacity, blended over the frame; with THUMBNAIL, an HDR angle map (the map being baked)
// drawn small and tone-mapped by x / (1 + x).
uniform sampler2D image;

in vec2 uv;
out vec4 colour;

void main() {
#ifdef THUMBNAIL
    vec3 c = texture(image, vec2(uv.x, 1.0 - uv.y)).rgb;  // the output's rows run from the top, the map's t up
    colour = vec4(pow(c / (1.0 + c), vec3(1.0 / 2.2)), 1.0);
#else
    float c = texture(image, uv).r;  // one texel per pixel: the viewport is the text's size
    colour = vec4(vec3(c), max(c, float(BOX_ALPHA) / 255.0));  // (overlay_image's colour and alpha)
#endif
}
