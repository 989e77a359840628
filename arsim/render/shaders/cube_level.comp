#version 430
// One mip level of a cube map written from a storage buffer: texel (x, y) of face z (+X, -X, +Y, -Y, +Z,
// -Z) at buffer index (z * size + y) * size + x, row y = 0 at the face's t = -1 (GL's first row).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
layout(std430, binding = 0) readonly buffer Texels { vec4 texels[]; };
layout(rgba32f, binding = 0) writeonly uniform imageCube level;
uniform int size;

void main() {
    ivec3 p = ivec3(gl_GlobalInvocationID);
    if (p.x >= size || p.y >= size) {
        return;
    }
    imageStore(level, p, texels[(p.z * size + p.y) * size + p.x]);
}
