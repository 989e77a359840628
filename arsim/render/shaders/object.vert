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
#ifdef PRT_VERTEX
// Precomputed radiance transfer per vertex: the coefficients Renderer.relight wrote, (count, 3) per vertex
// in the mesh's order, interpolated to the fragments like any vertex value (the spec's section 4).
layout(std430, binding = 0) readonly buffer PrtCoefficients { float prt[]; };
out vec3 v_prt[BASIS_COUNT];
#endif

void main() {
    vec4 world = model * vec4(in_position, 1.0);
    v_world = world.xyz;
    v_normal = normal_matrix * in_normal;
    v_tangent = normal_matrix * in_tangent;
    v_uv = in_uv;
    v_uv2 = in_uv2;
    gl_Position = view_projection * world;
#ifdef PRT_VERTEX
    for (int k = 0; k < BASIS_COUNT; k++) {
        int i = (gl_VertexID * BASIS_COUNT + k) * 3;
        v_prt[k] = vec3(prt[i], prt[i + 1], prt[i + 2]);
    }
#endif
}
