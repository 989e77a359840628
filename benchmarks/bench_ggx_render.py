"""Render cost of GGX materials against Phong (prints figures; not a test): the same objects along the
default scenario's AR path, once with the thesis's Phong materials and once as GGX (material = ggx), in
the same run: a row of ten ray-cast spheres and the normal-mapped torus with its AO light map. Step 5
(the objects) per frame: GL time (timer query) and CPU time around glFinish, median and p95 over the
frames where the tag is in view (the two materials interleaved frame by frame), and the best of 20 draws
at the path's nearest view (CPU time around glFinish: the steadiest figure on a shared machine); and the
one-time costs, the probe's GGX chain and the split sum's table.

    python benchmarks/bench_ggx_render.py [--frames N] [--width W --height H]
"""

import argparse
import time

import numpy as np
from timing import best_of

from arsim.core.assets import assets_dir
from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.fast import fast_maps
from arsim.lighting.ggx import brdf_lut
from arsim.lighting.mapset import MapSet
from arsim.render.content import ggx_chain, light_objects, scene_objects
from arsim.render.renderer import Renderer
from arsim.scenario.loader import parse_scenario
from arsim.sensors.recording import ar_path

OBJECTS = {
    "sphere row": '[[render.objects]]\nkind = "sphere_row"\nposition_m = [0.0, -0.06]\nsize_m = 0.016\n',
    "torus": '[[render.objects]]\nkind = "torus"\nsize_m = 0.05\n',
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=40, help="frames spread over the path (default 40)")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    args = parser.parse_args()

    env = to_layout(read_hdr(assets_dir() / "envmaps" / "interior.exr"), "anglemap", 256)
    start = time.perf_counter()
    brdf_lut()
    lut_s = time.perf_counter() - start
    start = time.perf_counter()
    ggx_chain(env)
    chain_s = time.perf_counter() - start
    ctx = create_gl_context()
    print(f"{ctx.info['GL_RENDERER']}; one-time: the split sum's table {lut_s:.2f} s, the probe's GGX chain "
          f"(128 x 128 faces, 6 levels) {chain_s:.2f} s")
    print(f"objects at {args.width}x{args.height}; step 5 (objects) in ms")
    print(f"{'objects':<14} {'material':<8} {'GL p50':>8} {'GL p95':>8} {'CPU p50':>8} {'CPU p95':>8} {'nearest':>9}")
    best = {}
    for name, text in OBJECTS.items():
        renderers, scenario = {}, None
        for material in ("phong", "ggx"):
            scenario = parse_scenario(text + f'material = "{material}"\n')
            objects = light_objects(scene_objects(scenario.render), env)
            exponents = sorted({1.0} | {o.material.exponent for o in objects})
            camera = CameraIntrinsics.from_fov(args.width, args.height, scenario.device.camera.hfov_deg)
            renderers[material] = Renderer(camera, MapSet.of("fast", exponents, fast_maps(env, exponents)), ctx)
            for o in objects:
                renderers[material].add(o)
        path = ar_path(scenario)
        t = np.linspace(0.0, path.duration, args.frames)
        t = t[path._away(t) == 0.0]
        cam_to_world, positions = path.camera_orientation(t), path.position(t)
        query = ctx.query(time=True)
        gl, cpu = {m: [] for m in renderers}, {m: [] for m in renderers}
        for n in range(len(t) + 3):
            k = max(n - 3, 0)  # the first three frames compile and allocate
            rotation = cam_to_world[k].inv()
            for material, renderer in renderers.items():  # (interleaved: the machine's other load falls on both alike)
                ctx.finish()
                start = time.perf_counter()
                with query:
                    renderer.render_objects(rotation, -rotation.apply(positions[k]))
                ctx.finish()
                if n >= 3:
                    cpu[material].append(1000 * (time.perf_counter() - start))
                    gl[material].append(query.elapsed / 1e6)
        near = int(np.argmin(np.linalg.norm(positions, axis=1)))  # the nearest view: the most pixels, the least noise
        rotation = cam_to_world[near].inv()
        for material, renderer in renderers.items():
            def draw():
                renderer.render_objects(rotation, -rotation.apply(positions[near]))
                ctx.finish()
            best[name, material] = 1000 * best_of(20, draw)
        for material in renderers:
            g, c = gl[material], cpu[material]
            print(f"{name:<14} {material:<8} {np.median(g):8.2f} {np.percentile(g, 95):8.2f} {np.median(c):8.2f} "
                  f"{np.percentile(c, 95):8.2f} {best[name, material]:9.2f}")

if __name__ == "__main__":
    main()
