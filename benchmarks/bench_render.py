"""Render speed at 1280 x 720 (prints figures; not a test): the objects pass (thesis 5.1 steps 4-6: the
virtual objects into the HDR colour and the mask, with IBL, light maps and normal maps) and the tone
mapping pass (step 7, mip chains included), each timed with GL timer queries and on the CPU (with
glFinish), median over the frames.

    python benchmarks/bench_render.py [--frames N] [--width W --height H]
"""

import argparse
import time

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.fast import fast_maps
from arsim.render.content import SPHERE_EXPONENTS, scene_objects
from arsim.render.renderer import Renderer
from arsim.scenario.sections import RenderSection


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    args = parser.parse_args()
    from pathlib import Path

    env = to_layout(read_hdr(Path(__file__).resolve().parents[1] / "assets" / "envmaps" / "interior.exr"), "anglemap", 256)
    exponents = (1.0,) + tuple(e for e in SPHERE_EXPONENTS if e != 1.0)
    maps = dict(zip(exponents, fast_maps(env, exponents)))
    ctx = create_gl_context()
    camera = CameraIntrinsics.from_fov(args.width, args.height, 60.0)
    renderer = Renderer(camera, maps, ctx)
    for obj in scene_objects(RenderSection()):  # the default scene
        renderer.add(obj)
    eye, target = np.array([0.05, 0.3, 0.35]), np.array([0.0, 0.02, -0.03])
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    rotation = np.stack([x, np.cross(z, x), z])
    background = np.full((args.height, args.width, 3), 100, np.uint8)
    times = {"objects (steps 4-6)": ([], []), "tone mapping (step 7)": ([], [])}
    query = ctx.query(time=True)
    for frame in range(args.frames + 3):
        for name, work in (("objects (steps 4-6)", lambda: renderer.render_objects(Rotation.from_matrix(rotation), -rotation @ eye)),
                           ("tone mapping (step 7)", lambda: renderer.tonemap_pass(background))):
            ctx.finish()
            start = time.perf_counter()
            with query:
                work()
            ctx.finish()
            if frame >= 3:  # the first frames compile and allocate
                times[name][0].append(1000 * (time.perf_counter() - start))
                times[name][1].append(query.elapsed / 1e6)
    print(f"{args.width} x {args.height}, {len(renderer.objects)} objects, {args.frames} frames, median ms:")
    total_cpu = total_gl = 0.0
    for name, (cpu, gl) in times.items():
        total_cpu, total_gl = total_cpu + np.median(cpu), total_gl + np.median(gl)
        print(f"  {name:24s} CPU {np.median(cpu):7.2f}   GL {np.median(gl):7.2f}")
    print(f"  {'steps 4-7':24s} CPU {total_cpu:7.2f}   GL {total_gl:7.2f}")


if __name__ == "__main__":
    main()
