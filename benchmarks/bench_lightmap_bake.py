"""Time of baking a scenario's directional light maps and irradiance volume (prints figures; not a test):
`light_objects` as `arsim render`, `run` and `profile` call it, from an environment resampled to an angle
map (the captured probe's stand-in): what each object takes (texels, grid points), then the seconds of
each run.

    python benchmarks/bench_lightmap_bake.py [SCENARIO] [--env FILE] [--size N] [--runs K]
"""

import argparse
import time
from pathlib import Path

import numpy as np

from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.render.content import VOLUME_GRID, light_objects, scene_objects
from arsim.scenario import load_scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scenario", nargs="?", default="scenarios/inm.toml", type=Path)
    parser.add_argument("--env", default="assets/envmaps/courtyard.exr", type=Path)
    parser.add_argument("--size", type=int, default=64, help="N of the N x N angle map the light is resampled to")
    parser.add_argument("--runs", type=int, default=2)
    args = parser.parse_args()
    objects = scene_objects(load_scenario(args.scenario).render)
    light = to_layout(read_hdr(args.env), "anglemap", args.size)
    print(f"{args.scenario}: {len(objects)} objects, light {args.env.name} at {args.size}²")
    for k, obj in enumerate(objects):
        if obj.material.basis and obj.lightmap_surface is not None:
            print(f"  object {k}: inm-{obj.material.basis}, {np.count_nonzero(obj.lightmap_surface().valid)} texels")
        elif obj.material.volume_lit:
            print(f"  object {k}: volume, {np.prod(VOLUME_GRID)} grid points")
    for run in range(args.runs):
        start = time.perf_counter()
        light_objects(objects, light)
        print(f"baked in {time.perf_counter() - start:.1f} s")

if __name__ == "__main__":
    main()
