"""Render cost of irradiance normal mapping per basis at 1280 x 720 (prints figures; not a test): the
default scenario's torus (normal-mapped) drawn along its AR path with each lighting: IBL (the irradiance
map at the perturbed normal), the thesis's AO light map times it, and a directional light map (32 x 64
texels) in each basis and count, also at the spec's lower levels of detail (the leading terms: constant,
then linear). Step 5 (the objects) per frame: GL time (timer query) and CPU time around glFinish,
median and p95 over the frames where the tag is in view. The coefficients' values do not change the
cost; they are drawn at random.

    python benchmarks/bench_inm_render.py [--frames N] [--width W --height H]
"""

import argparse
import dataclasses
import time

import numpy as np

from arsim.core.assets import assets_dir
from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.evaluate.compare_bases import entries
from arsim.lighting.fast import fast_maps
from arsim.render.content import scene_objects
from arsim.lighting.mapset import MapSet
from arsim.render.renderer import Renderer
from arsim.scenario.sections import Scenario
from arsim.sensors.recording import ar_path


def lightings():
    yield "ibl", {"light_map": None}
    yield "lightmap-ao", {}
    for name, count in entries():
        if name == "sh-rh":
            continue
        levels = sorted({1, min(count, 4), count} if name not in ("hl2",) else {count})
        if name == "zernike":
            levels = sorted({1, 3, count})
        for terms in levels:
            label = f"inm-{name}{count}" + ("" if terms == count else f" ({terms} term{'s' if terms > 1 else ''})")
            rng = np.random.default_rng(0)
            yield label, {"light_map": None, "directional_map": rng.uniform(-0.2, 1.0, (32, 64, count, 3)),
                          "basis": f"{name}{count}", "inm_terms": terms}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=40, help="frames spread over the path (default 40)")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    args = parser.parse_args()

    scenario = Scenario()
    env = to_layout(read_hdr(assets_dir() / "envmaps" / "interior.exr"), "anglemap", 256)
    torus = next(o for o in scene_objects(scenario.render) if o.material.normal_map is not None)
    exponents = [1.0, torus.material.exponent]
    maps = MapSet.of("fast", exponents, fast_maps(env, exponents))
    ctx = create_gl_context()
    camera = CameraIntrinsics.from_fov(args.width, args.height, scenario.device.camera.hfov_deg)
    path = ar_path(scenario)
    t = np.linspace(0.0, path.duration, args.frames)
    t = t[path._away(t) == 0.0]
    cam_to_world, positions = path.camera_orientation(t), path.position(t)
    query = ctx.query(time=True)
    print(f"torus at {args.width}x{args.height}, {len(t)} frames of the AR path; step 5 (objects) in ms")
    print(f"{'lighting':<28} {'GL p50':>8} {'GL p95':>8} {'CPU p50':>8}")
    for label, changes in lightings():
        renderer = Renderer(camera, maps, ctx)
        renderer.add(dataclasses.replace(torus, material=dataclasses.replace(torus.material, **changes)))
        gl, cpu = [], []
        for n in range(len(t) + 3):
            k = max(n - 3, 0)  # the first three frames compile and allocate
            rotation = cam_to_world[k].inv()
            ctx.finish()
            start = time.perf_counter()
            with query:
                renderer.render_objects(rotation, -rotation.apply(positions[k]))
            ctx.finish()
            if n >= 3:
                cpu.append(1000 * (time.perf_counter() - start))
                gl.append(query.elapsed / 1e6)
        print(f"{label:<28} {np.median(gl):8.2f} {np.percentile(gl, 95):8.2f} {np.median(cpu):8.2f}")


if __name__ == "__main__":
    main()
