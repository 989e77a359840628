// Thesis Alg. 5.3: the vertex's world position, and its normal and tangent turned into world space by
// the normal matrix (the bitangent is rebuilt per fragment).
uniform mat4 model;
uniform mat4 view_projection;   // OpenGL projection x view
uniform mat3 normal_matrix;     // inverse transpose of the model matrix's 3 x 3 part

in vec3 in_position;
in vec3 in_normal;
in vec3 in_tangent;
in vec2 in_uv;                  // first UV set: normal map
in vec2 in_uv2;                 // second UV set: light map

out vec3 v_world;
out vec3 v_normal;
out vec3 v_tangent;
out vec2 v_uv;
out vec2 v_uv2;

void main() {
    vec4 world = model * vec4(in_position, 1.0);
    v_world = world.xyz;
    v_normal = normal_matrix * in_normal;
    v_tangent = normal_matrix * in_tangent;
    v_uv = in_uv;
    v_uv2 = in_uv2;
    gl_Position = view_projection * world;
}
