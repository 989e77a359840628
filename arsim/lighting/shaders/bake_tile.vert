// The quad of one tile (thesis Alg. 4.1's vertex stage): the unit square scaled by tileScale and moved
// to tileOffset, both in the map's texture coordinates (s right, t up), then to clip space.
uniform vec2 tile_offset;
uniform float tile_scale;

void main() {
    const vec2 corners[6] = vec2[](vec2(0, 0), vec2(1, 0), vec2(0, 1), vec2(0, 1), vec2(1, 0), vec2(1, 1));
    vec2 st = tile_offset + tile_scale * corners[gl_VertexID];
    gl_Position = vec4(st * 2.0 - 1.0, 0.0, 1.0);
}
