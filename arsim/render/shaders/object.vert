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
// With PRT_CPCA the transfer is clustered (Sloan 2003): prt holds per cluster its mean's and its
// PRT_VECTORS principal matrices' coefficients, and prt_weights per vertex its cluster and weights.
layout(std430, binding = 0) readonly buffer PrtCoefficients { float prt[]; };
#ifdef PRT_CPCA
layout(std430, binding = 1) readonly buffer PrtWeights { float prt_weights[]; };
#endif
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
#ifdef PRT_CPCA
    int w = gl_VertexID * (PRT_VECTORS + 1);
    int cluster = int(prt_weights[w]);
    int stride = BASIS_COUNT * 3;
    for (int k = 0; k < BASIS_COUNT; k++) {
        int i = cluster * (PRT_VECTORS + 1) * stride + k * 3;
        vec3 c = vec3(prt[i], prt[i + 1], prt[i + 2]);
        for (int j = 1; j <= PRT_VECTORS; j++) {
            int q = i + j * stride;
            c += prt_weights[w + j] * vec3(prt[q], prt[q + 1], prt[q + 2]);
        }
        v_prt[k] = c;
    }
#else
    for (int k = 0; k < BASIS_COUNT; k++) {
        int i = (gl_VertexID * BASIS_COUNT + k) * 3;
        v_prt[k] = vec3(prt[i], prt[i + 1], prt[i + 2]);
    }
#endif
#endif
}
