// The accurate maps of a tile from its sums (bake_accurate.frag): M_s = sum f L W / sum f W, 0 where the
// lobe met no texel (outside the disk).
uniform sampler2D sums[MAPS];

layout(location = 0) out vec4 maps[MAPS];

void main() {
    for (int k = 0; k < MAPS; k++) {
        vec4 s = texelFetch(sums[k], ivec2(gl_FragCoord.xy), 0);
        maps[k] = vec4(s.w > 0.0 ? s.rgb / s.w : vec3(0.0), 1.0);
    }
}
