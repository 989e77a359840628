"""Time per map method at 128², 256² and 512² (prints a table; not a test).

    python benchmarks/bench_maps.py [--env assets/envmaps/courtyard.exr] [--spec 1,2,10,20,40,80,160,320,1280]

`accurate` and `bounds` cost N^4: at 256² and 512² they are timed on --texels output texels and the
time is scaled to the whole disk (marked "scaled"). SH is timed at orders 35 (the thesis's) and 128.
"""

import argparse
import time
from pathlib import Path

import numpy as np

from arsim.core.assets import assets_dir
from arsim.core.conventions import anglemap_disk_mask
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.accurate import BLOCK, Tile, accurate_maps
from arsim.lighting.methods import MapParameters, bake


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", type=Path, default=assets_dir() / "envmaps" / "courtyard.exr")
    parser.add_argument("--spec", default="1,2,10,20,40,80,160,320,1280")
    parser.add_argument("--sizes", default="128,256,512")
    parser.add_argument("--texels", type=int, default=256, help="output texels timed for accurate/bounds above 128²")
    args = parser.parse_args()
    exponents = [float(s) for s in args.spec.split(",")]
    source = read_hdr(args.env)
    rows = [("accurate", MapParameters()), ("bounds", MapParameters()), ("fast", MapParameters()),
            ("mipmap", MapParameters()), ("sh (order 35)", MapParameters(sh_order=35)),
            ("sh (order 128)", MapParameters(sh_order=128)), ("mc (64 samples)", MapParameters(samples=64))]
    sizes = [int(s) for s in args.sizes.split(",")]
    print(f"{len(exponents)} maps, exponents {args.spec}, environment {args.env.name}\n")
    print(f"{'method':<18}" + "".join(f"{f'{n}²':>18}" for n in sizes))
    for label, params in rows:
        name = label.split()[0]
        cells = []
        for n in sizes:
            env = to_layout(source, "anglemap", n)
            disk = int(anglemap_disk_mask(n).sum())
            if name in ("accurate", "bounds") and n > 128:
                # Whole 8 x 8 tiles (the bounds method prunes per tile), spread over the disk, timed and scaled.
                inside = anglemap_disk_mask(n)
                rng = np.random.default_rng(0)
                chosen, computed = [], 0
                while computed < args.texels:
                    r, c = (rng.integers(0, n // BLOCK, 2) * BLOCK).tolist()
                    if inside[r:r + BLOCK, c:c + BLOCK].all():
                        chosen.append(Tile(r, c, BLOCK))
                        computed += BLOCK * BLOCK
                threshold = 0.03 if name == "bounds" else None
                start = time.perf_counter()
                for tile in chosen:
                    accurate_maps(env, exponents, tile=tile, bounds_threshold=threshold)
                cells.append(f"{(time.perf_counter() - start) * disk / computed:>11.1f} s scaled")
            else:
                result = bake(env, exponents, name, params)
                cells.append(f"{result.seconds_total:>16.2f} s")
        print(f"{label:<18}" + "".join(f"{c:>18}" for c in cells))


if __name__ == "__main__":
    main()
