"""GL bake accuracy (prints figures; not a test): the accurate, bounds and SH maps baked on the GL path,
untiled and in 16² tiles, against the NumPy oracles (accurate.py; sh.py's direct float64 sum of the same
coefficients): the largest relative error (SH: where the value is at least 1 % of the map's largest,
and against the map's largest everywhere).

    python benchmarks/gl_bake_accuracy.py [--size N]
"""

import argparse

import numpy as np

from arsim.core.assets import assets_dir
from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.accurate import accurate_maps
from arsim.lighting.gl_bake import gl_accurate_maps, gl_sh_maps
from arsim.lighting.phong import phong_zonal_coefficients
from arsim.lighting.sh import sh_coefficients, sh_evaluate

EXPONENTS = [1, 10, 20, 40, 80, 160, 320, 640]


def relative(test: np.ndarray, reference: np.ndarray) -> float:
    inside = reference > 0
    return float((np.abs(test - reference)[inside] / reference[inside]).max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=64, help="N of the N x N probe and maps (default 64)")
    n = parser.parse_args().size
    env = to_layout(read_hdr(assets_dir() / "envmaps" / "interior.exr"), "anglemap", n)
    ctx = create_gl_context()
    print(f"{n}² maps, exponents {EXPONENTS}, largest relative error against NumPy:")
    for name, threshold in (("accurate", None), ("bounds 0.03", 0.03)):
        reference = accurate_maps(env, EXPONENTS, bounds_threshold=threshold)
        for tile in (None, 16):
            maps = gl_accurate_maps(env, EXPONENTS, tile, ctx, threshold)
            print(f"  {name:12s} {'untiled' if tile is None else f'{tile}² tiles':10s} {relative(maps, reference):.2e}")
    coeffs = sh_coefficients(env, 35)
    kappas = np.stack([phong_zonal_coefficients(s, 35) for s in EXPONENTS])
    inside = anglemap_disk_mask(n)
    reference = np.zeros((len(EXPONENTS), n, n, 3))
    reference[:, inside] = sh_evaluate(coeffs, kappas, anglemap_directions(n)[inside])[..., :3]
    scale = np.abs(reference).max(axis=(1, 2, 3), keepdims=True)
    large = np.abs(reference) >= 0.01 * scale
    for tile in (None, 16):
        maps = gl_sh_maps(env, EXPONENTS, 35, tile, ctx, coeffs)
        print(f"  {'sh order 35':12s} {'untiled' if tile is None else f'{tile}² tiles':10s} "
              f"{(np.abs(maps - reference)[large] / np.abs(reference)[large]).max():.2e} where >= 1 % of the largest, "
              f"{(np.abs(maps - reference) / scale).max():.2e} of the largest")


if __name__ == "__main__":
    main()
