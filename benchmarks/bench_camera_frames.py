"""The recording's GL camera frames, timed per frame (prints figures; not a test).

    python benchmarks/bench_camera_frames.py [--scenario FILE] [--frames 200] [--repeat 3]

For each segment of the scenario (the sweep, and the AR path with the table and tag), `CameraRenderer.capture`
of its first frames along its trajectory at a fixed exposure: the wall time and the CPU time of the process
(all threads: llvmpipe shades on every core) per frame, the median over the repeats. Beside it, the floor in
the same context and interleaved run by run: a compute shader that writes a constant to every pixel of the
same buffer, read back the same way (the dispatch, the barrier, the finish and the read-back, no shading).
"""

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from arsim.scenario import load_scenario
from arsim.scenario.environment import load_environment
from arsim.sensors.camera import ResponseCurve, SensorSettings
from arsim.sensors.recording import camera_intrinsics, camera_mount, recording_segments
from arsim.sensors.views import CameraRenderer

FLOOR = """#version 430
layout(local_size_x = 64, local_size_y = 1) in;
layout(std430, binding = 0) writeonly buffer Codes { uint codes[]; };
uniform int width;
uniform int height;
void main() {
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
    if (pixel.x >= width || pixel.y >= height) return;
    codes[pixel.y * width + pixel.x] = 0xFF808080u;
}
"""


def _timed(step, n: int) -> tuple[float, float]:
    """(wall, CPU) milliseconds per call of step(k) over k < n."""
    wall, cpu = time.perf_counter(), time.process_time()
    for k in range(n):
        step(k)
    return (time.perf_counter() - wall) / n * 1e3, (time.process_time() - cpu) / n * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", type=Path, help="scenario file (default: the embedded default)")
    parser.add_argument("--frames", type=int, default=200, help="frames of each segment per run (default 200)")
    parser.add_argument("--repeat", type=int, default=3, help="runs, alternating with the floor (default 3)")
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    probe = load_environment(scenario.environment)
    cam = scenario.device.camera
    camera, mount = camera_intrinsics(scenario), camera_mount(scenario.device.camera_misalignment_deg)
    response = ResponseCurve(cam.response, cam.gamma, cam.contrast)
    print(f"{cam.width} x {cam.height}, {args.frames} frames a run, median of {args.repeat} runs, ms per frame:")
    print(f"  {'segment':10} {'wall':>7} {'CPU':>7} {'floor wall':>11} {'floor CPU':>10} {'wall / floor':>13}")
    for segment in recording_segments(scenario):
        times = np.arange(args.frames) / cam.fps
        views, positions = segment.trajectory.camera_orientation(times, mount), segment.trajectory.position(times)
        renderer = CameraRenderer(probe, camera, SensorSettings.of(cam), response, table=segment.table)
        floor = renderer.ctx.compute_shader(FLOOR)
        floor["width"].value, floor["height"].value = cam.width, cam.height

        def frame(k):
            renderer.capture(views[k], 0.01, 100.0, k, positions[k])

        def constant(k):
            renderer.codes.bind_to_storage_buffer(0)
            floor.run(-(-cam.width // renderer.GROUP), cam.height)
            renderer.ctx.memory_barrier()
            renderer.ctx.finish()
            np.frombuffer(renderer.codes.read(), dtype=np.uint8)

        frame(0), constant(0)  # (shaders compiled, textures resident)
        runs = [(_timed(frame, args.frames), _timed(constant, args.frames)) for _ in range(args.repeat)]
        wall, cpu = statistics.median(r[0][0] for r in runs), statistics.median(r[0][1] for r in runs)
        floor_wall, floor_cpu = statistics.median(r[1][0] for r in runs), statistics.median(r[1][1] for r in runs)
        print(f"  {segment.name:10} {wall:7.2f} {cpu:7.2f} {floor_wall:11.2f} {floor_cpu:10.2f} {wall / floor_wall:12.2f}x")
        floor.release()
        renderer.release()


if __name__ == "__main__":
    main()
