"""Frame rate of PRT with normal maps per variant (the normal-mapping-prt spec's table 1, on this machine;
prints figures and writes benchmarks/results/bench_prt.json; not a test).

Two scenes, the normal-mapped torus on the table seen from 0.25 m at 1280 x 720: simple (36 x 18 quads,
1 296 faces) and complex (246 x 123, 60 516 faces). Per vertex, the transfer at order L (shadows by the
torus and the table, computed once). Per variant and frame: the CPU relight (the per-vertex matrices
times the light's SH, then the upload of the coefficients) and the GL evaluation (step 5, timer query),
medians over the frames; the floor beside them is the same torus lit by the irradiance map (IBL), in
the same run. Then CPCA of the complex scene's matrices: relight time and the coefficients' error
against the uncompressed ones under three probes.

    python benchmarks/bench_prt.py [--frames 30] [--order 5] [--samples 512]
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.assets import assets_dir
from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.evaluate.inm_compare import MAJOR, MINOR, _blocked
from arsim.lighting import prt
from arsim.lighting.fast import fast_maps
from arsim.lighting.mapset import MapSet
from arsim.render.content import ridges_normal_map, torus
from arsim.render.renderer import Material, Renderer, SceneObject
from arsim.render.transfer import vertex_frames

RESULTS = Path(__file__).resolve().parent / "results"
SCENES = {"simple": (36, 18), "complex": (246, 123)}


def view(distance=0.25, elevation_deg=35.0):
    e = np.radians(elevation_deg)
    eye = np.array([0.0, MINOR + distance * np.sin(e), distance * np.cos(e)])
    z = np.array([0.0, MINOR, 0.0]) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    r = np.stack([x, np.cross(z, x), z])
    return r, -r @ eye


def probes():
    return {name: to_layout(read_hdr(assets_dir() / "envmaps" / f"{name}.exr"), "anglemap", 128)
            for name in ("interior", "sunrise", "city")}


def timed_frames(renderer, ctx, frames, relight=None):
    """Median CPU relight ms and GL step-5 ms over frames (the first three warm up)."""
    query = ctx.query(time=True)
    r, t = view()
    cpu, gl = [], []
    for n in range(frames + 3):
        yaw = Rotation.from_rotvec([0.0, 0.02 * n, 0.0]).as_matrix()  # (a camera that moves a little)
        start = time.perf_counter()
        if relight is not None:
            relight()
        relight_ms = 1000 * (time.perf_counter() - start)
        ctx.finish()
        with query:
            renderer.render_objects(Rotation.from_matrix(r @ yaw), t)
        ctx.finish()
        if n >= 3:
            cpu.append(relight_ms)
            gl.append(query.elapsed / 1e6)
    return float(np.median(cpu)), float(np.median(gl))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--order", type=int, default=prt.DEFAULT_ORDER)
    parser.add_argument("--samples", type=int, default=512, help="directions per vertex of the transfer")
    parser.add_argument("--clusters", type=int, default=256, help="CPCA clusters (4 principal vectors each)")
    args = parser.parse_args()

    ctx = create_gl_context()
    camera = CameraIntrinsics.from_fov(1280, 720, 60.0)
    lights = {name: prt.light_sh(p, args.order) for name, p in probes().items()}
    env = probes()["interior"]
    maps = MapSet.of("fast", (1.0, 80.0), fast_maps(env, (1.0, 80.0)))
    normal_map = ridges_normal_map()
    results = {"order": args.order, "samples": args.samples, "frames": args.frames, "scenes": {}}
    print(f"PRT per vertex at 1280 x 720, order {args.order}; ms per frame, medians over {args.frames} frames")
    for scene, (rings, segments) in SCENES.items():
        mesh = torus(MAJOR, MINOR, rings, segments)
        start = time.perf_counter()
        transfer = prt.compute_transfer(*vertex_frames(mesh, np.eye(4)), args.order, _blocked, args.samples)
        transfer_s = time.perf_counter() - start
        floor_renderer = Renderer(camera, maps, ctx)
        floor_renderer.add(SceneObject(mesh, Material((0.6, 0.6, 0.6), (0.0, 0.0, 0.0), 80.0, normal_map=normal_map)))
        _, floor_gl = timed_frames(floor_renderer, ctx, args.frames)
        row = {"faces": int(len(mesh.indices)), "vertices": int(len(mesh.positions)), "transfer_s": transfer_s,
               "ibl_gl_ms": floor_gl, "variants": {}}
        print(f"{scene}: {len(mesh.indices)} faces, {len(mesh.positions)} vertices, transfer {transfer_s:.1f} s; "
              f"IBL (floor) GL {floor_gl:.2f} ms")
        print(f"  {'variant':<8} {'relight':>8} {'GL':>7} {'GL/IBL':>7} {'frames/s':>9}")
        def renderer_of(name, matrices, compressed=None):
            renderer = Renderer(camera, maps, ctx)
            renderer.add(SceneObject(mesh, Material((0.6, 0.6, 0.6), (0.0, 0.0, 0.0), 80.0, normal_map=normal_map,
                                                    prt_variant=name, prt_matrices=matrices, prt_compressed=compressed)))
            return renderer

        for name in prt.VARIANTS:
            renderer = renderer_of(name, prt.variant_transfer(transfer, prt.get_variant(name)))
            light = lights["interior"]
            cpu, gl = timed_frames(renderer, ctx, args.frames, lambda: renderer.relight(light))
            row["variants"][name] = {"relight_ms": cpu, "gl_ms": gl, "fps": 1000 / (cpu + gl)}
            print(f"  {name:<8} {cpu:8.2f} {gl:7.2f} {gl / floor_gl:7.2f} {1000 / (cpu + gl):9.1f}")
        if scene == "complex":
            row["cpca"] = cpca(transfer, lights, args.clusters, mesh, renderer_of, ctx, args.frames)
        results["scenes"][scene] = row
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "bench_prt.json").write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {RESULTS / 'bench_prt.json'}")


def cpca(transfer, lights, clusters, mesh, renderer_of, ctx, frames):
    """Per variant: the relight product alone, plain and CPCA (per cluster; the GPU sums per vertex), ms
    (best of 20); the CPCA frame's relight (with the upload) and GL ms; and the compressed coefficients'
    RMS error relative to the plain ones' RMS, per probe."""
    out = {}
    print(f"  CPCA, {clusters} clusters x 4 vectors: relight product (no upload) and frame, ms; error of the coefficients")
    for name in ("gs", "sep-c"):
        matrices = prt.variant_transfer(transfer, prt.get_variant(name))
        start = time.perf_counter()
        compressed = prt.compress(matrices, clusters)
        compress_s = time.perf_counter() - start
        light = lights["interior"]
        plain = best_of(20, lambda: prt.relight(matrices, light))
        packed = best_of(20, lambda: compressed.cluster_coefficients(light))
        renderer = renderer_of(name, matrices, compressed)
        cpu, gl = timed_frames(renderer, ctx, frames, lambda: renderer.relight(light))
        errors = {}
        for probe, l in lights.items():
            exact, approx = prt.relight(matrices, l), compressed.relight(l)
            errors[probe] = float(np.sqrt(np.mean((approx - exact) ** 2) / np.mean(exact ** 2)))
        out[name] = {"plain_ms": plain, "cpca_ms": packed, "frame_relight_ms": cpu, "frame_gl_ms": gl,
                     "compress_s": compress_s, "error": errors}
        print(f"  {name:<8} product: plain {plain:6.2f}, CPCA {packed:6.3f}; frame: relight {cpu:6.3f}, GL {gl:6.2f} "
              f"(compression {compress_s:.1f} s); error " + ", ".join(f"{p} {100 * e:.2f} %" for p, e in errors.items()))
    return out


def best_of(repeat, fn):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1000 * min(times)


if __name__ == "__main__":
    main()
