// Step 7: the overlay's text image (white on a translucent box), blended over the frame; with
// THUMBNAIL, an HDR angle map (the map being baked) drawn small and tone-mapped by x / (1 + x).
uniform sampler2D image;

in vec2 uv;
out vec4 colour;

void main() {
#ifdef THUMBNAIL
    vec3 c = texture(image, vec2(uv.x, 1.0 - uv.y)).rgb;  // the output's rows run from the top, the map's t up
    colour = vec4(pow(c / (1.0 + c), vec3(1.0 / 2.2)), 1.0);
#else
    colour = texture(image, uv);     // one texel per pixel: the viewport is the text's size
#endif
}
