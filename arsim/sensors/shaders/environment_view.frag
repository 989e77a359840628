// Radiance of the environment (at infinity) seen through an OpenCV pinhole camera.
out vec4 radiance;

void main() {
    radiance = vec4(pixel_radiance(), 1.0);
}
