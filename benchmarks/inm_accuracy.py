"""A normal-mapped torus on the table lit three ways, against the per-pixel reference (irradiance
integrated per pixel with the perturbed normal and the visibility): through a baked directional light
map in each basis (float, and stored in 8 bits as the spec's 2.2.3), and through the thesis's irradiance
map times its AO light map. Prints FLIP and the relative mean squared error per probe (not a test).

    python benchmarks/inm_accuracy.py [--envs interior.exr,sunrise.exr,city.exr] [--size 160x120] [--bases modh6,h4,hl2,sh9] [--images DIR]
"""

import argparse
import time
from pathlib import Path

from arsim.core.assets import assets_dir
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.evaluate.compare_bases import parse_entries
from arsim.evaluate.inm_compare import compare_on_torus, comparison_strip, scores
from arsim.lighting.bases import get_basis

ASSETS = assets_dir() / "envmaps"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", default="interior.exr,sunrise.exr,city.exr")
    parser.add_argument("--size", default="160x120", help="WxH of the view")
    parser.add_argument("--bases", default="modh6,h4,hl2,sh9", help="bases with counts")
    parser.add_argument("--images", metavar="DIR", help="also write each probe's renders side by side there")
    args = parser.parse_args()
    width, height = map(int, args.size.split("x"))
    entries = parse_entries(args.bases.split(","))
    print(f"torus {width}x{height}, light maps 32 x 64, probe summed at 32², FLIP (LDR) and relative MSE against the per-pixel reference")
    print(f"{'probe':<14} {'lighting':<22} {'FLIP':>8} {'MSE':>9}")
    for env in args.envs.split(","):
        probe = to_layout(read_hdr(ASSETS / env), "anglemap", 64)
        start = time.perf_counter()
        lightings = [(get_basis(name), count, q) for name, count in entries for q in (False, True)]
        comparison = compare_on_torus(probe, lightings, width, height)
        for label, result in scores(comparison).items():
            print(f"{env:<14} {label:<22} {result['flip']:8.4f} {result['mse']:9.5f}", flush=True)
        if args.images:
            Path(args.images).mkdir(parents=True, exist_ok=True)
            comparison_strip(comparison, Path(args.images) / f"inm_{Path(env).stem}.png")
        print(f"({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
