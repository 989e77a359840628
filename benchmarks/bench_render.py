"""Render speed at 1280 x 720 along the default scenario's AR path (prints figures; not a test): thesis
5.1 steps 4-7 per frame, the camera frame as the background (4), the virtual objects into the HDR colour
and the mask with IBL, light maps and normal maps (5), the masked tone mapping with its mip chain (6)
and the overlay (7), each timed on the CPU around glFinish and with GL timer queries; median, p95 and
max over the frames where the tag is in view (the look-away windows, which draw nothing, are left out).

    python benchmarks/bench_render.py [--frames N] [--width W --height H]
"""

import argparse
import time

import numpy as np

from arsim.core.assets import assets_dir
from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.fast import fast_maps
from arsim.render.content import scene_objects
from arsim.lighting.mapset import MapSet
from arsim.render.renderer import Renderer
from arsim.scenario.sections import Scenario
from arsim.sensors.recording import ar_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=60, help="frames spread over the path (default 60)")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    args = parser.parse_args()

    scenario = Scenario()
    env = to_layout(read_hdr(assets_dir() / "envmaps" / "interior.exr"), "anglemap", 256)
    objects = scene_objects(scenario.render)
    exponents = sorted({1.0} | {o.material.exponent for o in objects})
    maps = MapSet.of("fast", exponents, fast_maps(env, exponents))
    ctx = create_gl_context()
    camera = CameraIntrinsics.from_fov(args.width, args.height, scenario.device.camera.hfov_deg)
    renderer = Renderer(camera, maps, ctx)
    for obj in objects:
        renderer.add(obj)
    path = ar_path(scenario)
    t = np.linspace(0.0, path.duration, args.frames)
    t = t[path._away(t) == 0.0]  # the tag in view
    cam_to_world = path.camera_orientation(t)
    positions = path.position(t)
    background = np.random.default_rng(0).integers(0, 256, (args.height, args.width, 3), dtype=np.uint8)
    query = ctx.query(time=True)
    names = ("background (4)", "objects (5)", "tone mapping (6)", "overlay (7)")
    cpu, gl = np.zeros((len(t) + 3, 4)), np.zeros((len(t) + 3, 4))
    for n in range(len(t) + 3):
        k = max(n - 3, 0)  # the first three frames compile and allocate
        rotation = cam_to_world[k].inv()
        steps = (lambda: renderer.background_pass(background),
                 lambda: renderer.render_objects(rotation, -rotation.apply(positions[k])),
                 lambda: renderer.tonemap_pass(),
                 lambda: renderer.overlay_pass([f"frame {k}  16.0 ms", "maps: fast"]))
        for s, work in enumerate(steps):
            ctx.finish()
            start = time.perf_counter()
            with query:
                work()
            ctx.finish()
            cpu[n, s], gl[n, s] = 1000 * (time.perf_counter() - start), query.elapsed / 1e6
    cpu, gl = cpu[3:], gl[3:]
    print(f"{args.width} x {args.height}, {len(renderer.objects)} objects, {len(t)} frames of the default AR path "
          f"({np.linalg.norm(positions, axis=1).min():.2f}-{np.linalg.norm(positions, axis=1).max():.2f} m from the tag), ms:")
    print(f"  {'step':20s} {'CPU median':>10s} {'p95':>7s} {'max':>7s}   {'GL median':>9s} {'p95':>7s}")
    for s, name in enumerate(names + ("steps 4-7",)):
        c, g = (cpu[:, s], gl[:, s]) if s < 4 else (cpu.sum(axis=1), gl.sum(axis=1))
        print(f"  {name:20s} {np.median(c):10.2f} {np.percentile(c, 95):7.2f} {c.max():7.2f}   "
              f"{np.median(g):9.2f} {np.percentile(g, 95):7.2f}")


if __name__ == "__main__":
    main()
