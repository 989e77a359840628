// Radiance of the environment (at infinity) seen through an OpenCV pinhole camera.
out vec4 radiance;

void main() {
    radiance = vec4(pixel_radiance(ivec2(gl_FragCoord.xy)), 1.0);  // fragment (x, y) is pixel (x, y)
}
