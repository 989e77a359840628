"""Accuracy and speed of `fast` and `sh` against `accurate` on real assets (prints figures; not a test).

    python benchmarks/maps_accuracy.py [--assets city,courtyard,interior] [--texels 1000]

At 512² `accurate` costs N^4, so it is evaluated at --texels random disk texels plus the 14 x 14
texels around the brightest texel (where narrow lobes are hardest); at 128² at every texel.
Error per texel and channel |a - v| / (a + 1e-4 mean(a)), mean and max in percent (README: Conventions).
"""

import argparse
import time

import numpy as np
from timing import best_of

from arsim.core.assets import assets_dir
from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.evaluate.metrics import map_error
from arsim.lighting.accurate import accurate_maps, lobe_average_at
from arsim.lighting.fast import fast_maps
from arsim.lighting.methods import MapParameters, bake
from arsim.lighting.sh import sh_maps

EXPONENTS = [1, 2, 10, 20, 40, 80, 160, 320, 1280]
SH_ORDERS = [5, 10, 20, 35, 64, 128]


def reference_texels(env: np.ndarray, count: int, bright_patch: bool = True) -> np.ndarray:
    n = env.shape[0]
    inside = anglemap_disk_mask(n).ravel()
    picked = np.random.default_rng(0).choice(np.flatnonzero(inside), count, replace=False)
    if not bright_patch:
        return np.sort(picked)
    pr, pc = divmod(int(np.argmax(env[..., 1])), n)
    rows, cols = np.meshgrid(np.arange(pr - 7, pr + 7), np.arange(pc - 7, pc + 7), indexing="ij")
    near = (np.clip(rows, 0, n - 1) * n + np.clip(cols, 0, n - 1)).ravel()
    return np.unique(np.r_[picked, near[inside[near]]])


def row(errors) -> str:
    return "  ".join(f"{e.mean_percent:6.3f}/{e.max_percent:5.2f}" for e in errors)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--assets", default="city,courtyard,interior")
    parser.add_argument("--texels", type=int, default=1000)
    parser.add_argument("--no-bright-patch", action="store_true",
                        help="only uniformly drawn texels (the mean errors then weigh the disk evenly)")
    args = parser.parse_args()
    header = "  ".join(f"{f's={s}':>12}" for s in EXPONENTS)
    print("mean/max error (%) per exponent; fast at 512² against accurate at sampled texels, 128² at all\n")
    for name in args.assets.split(","):
        source = read_hdr(assets_dir() / "envmaps" / f"{name}.exr")
        env = to_layout(source, "anglemap", 512)
        texels = reference_texels(env, args.texels, not args.no_bright_patch)
        start = time.perf_counter()
        reference = lobe_average_at(env, EXPONENTS, anglemap_directions(512).reshape(-1, 3)[texels])
        ref_s = time.perf_counter() - start
        fast = bake(env, EXPONENTS, "fast")
        joint_s = best_of(3, lambda: fast_maps(env, EXPONENTS))
        errors = [map_error(reference[:, k], fast.maps[k].reshape(-1, 3)[texels]) for k in range(len(EXPONENTS))]
        print(f"{name} (accurate at {len(texels)} texels took {ref_s:.0f} s)")
        print(f"  {'':<22}{header}")
        print(f"  {'fast 512²':<22}{row(errors)}")
        print(f"  fast 512² time: {joint_s:.2f} s all nine maps together (best of 3); "
              f"{fast.seconds_total:.2f} s as a bake, map by map ({fast.seconds_shared:.2f} s shared)")

        small = to_layout(source, "anglemap", 128)
        inside = anglemap_disk_mask(128)
        exact = accurate_maps(small, EXPONENTS)
        fast_small = fast_maps(small, EXPONENTS)
        errors = [map_error(exact[k][inside], fast_small[k][inside]) for k in range(len(EXPONENTS))]
        print(f"  {'fast 128² (all texels)':<22}{row(errors)}")

        sh128 = min((bake(env, EXPONENTS, "sh", MapParameters(sh_order=128)) for _ in range(3)),
                    key=lambda r: r.seconds_total)
        print(f"  sh order 128 at 512²: {sh128.seconds_total:.2f} s coefficients and nine maps, best of 3 "
              f"({sh128.seconds_shared:.2f} s coefficients); all finite: {bool(np.isfinite(sh128.maps).all())}")
        print("  sh mean error (%) by order, s <= 320:")
        table = []
        for order in SH_ORDERS:
            maps = sh_maps(env, EXPONENTS, order).reshape(len(EXPONENTS), -1, 3)[:, texels]
            table.append([map_error(reference[:, k], maps[k]).mean_percent for k in range(len(EXPONENTS))])
            print(f"    order {order:>3}: " + "  ".join(f"{v:9.3f}" for v in table[-1]))
        rises = [f"s={s:g} from order {SH_ORDERS[i]} to {SH_ORDERS[i + 1]}" for k, s in enumerate(EXPONENTS) if s <= 320
                 for i in range(len(SH_ORDERS) - 1) if table[i + 1][k] >= table[i][k]]
        print(f"  sh error falls monotonically with order for every s <= 320: "
              f"{'yes' if not rises else 'no, it rises for ' + ', '.join(rises)}\n")


if __name__ == "__main__":
    main()
