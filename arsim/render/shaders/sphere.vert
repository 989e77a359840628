// A sphere's impostor: a quad through its centre, facing the camera, just large enough to hold its
// outline (the cone from the eye touching the sphere meets the quad's plane at r D / sqrt(D^2 - r^2) from
// the centre, D the eye's distance); object.frag ray-casts the sphere through it.
uniform mat4 view_projection;
uniform vec3 center;
uniform float radius;
uniform vec3 eye;

in vec2 in_corner;                  // (+-1, +-1)
out vec3 v_world;

void main() {
    vec3 w = center - eye;
    float distance = length(w);
    w /= distance;
    vec3 right = normalize(cross(w, abs(w.y) < 0.99 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0)));
    vec3 up = cross(right, w);
    float half_side = 1.01 * radius * distance / sqrt(max(distance * distance - radius * radius, 1e-12));
    v_world = center + half_side * (in_corner.x * right + in_corner.y * up);
    gl_Position = view_projection * vec4(v_world, 1.0);
}
