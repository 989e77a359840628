// Rectangles given by their corners in a target's pixels (from the bottom): the average's blocks.
uniform vec2 target_size;
in vec2 in_corner;

void main() {
    gl_Position = vec4(in_corner / target_size * 2.0 - 1.0, 0.0, 1.0);
}
