// Rectangles given by their corners in the frame's GL window pixels (from the bottom), drawn into the
// output, whose rows run from the image's top: y turns over (the tone mapping's objects' rectangles).
uniform vec2 frame_size;
in vec2 in_corner;

void main() {
    vec2 ndc = vec2(in_corner.x, frame_size.y - in_corner.y) / frame_size * 2.0 - 1.0;
    gl_Position = vec4(ndc, 0.0, 1.0);
}
