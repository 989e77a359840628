// Step 7: the overlay's text image (white on a translucent box), blended over the frame.
uniform sampler2D text;

in vec2 uv;
out vec4 colour;

void main() {
    colour = texture(text, uv);     // one texel per pixel: the viewport is the text's size
}
