"""GL bake speed (prints figures; not a test): the accurate, bounds and SH maps baked on the GL path
(arsim/lighting/gl_bake.py), one tile in the middle of the disk after a warm-up, timed with a GL timer
query; per method the time of the tile and the cost per unit of work (accurate: per output texel, input
texel and map; bounds: per output texel, candidate and map; SH: per output texel, SH term and map), and
from it the GL time a whole bake would take.

    python benchmarks/bench_bake.py [--size N] [--tile T] [--maps K]
"""

import argparse
import time
from pathlib import Path

import numpy as np

from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.accurate import Tile
from arsim.lighting.gl_bake import GLAccurateBaker, GLShBaker

EXPONENTS = (1, 5, 10, 20, 40, 80, 160, 320, 640, 1280)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=128, help="N of the N x N probe and maps (default 128)")
    parser.add_argument("--tile", type=int, default=16, help="side of the tile timed (default 16)")
    parser.add_argument("--maps", type=int, default=8, help="maps baked at once (default 8)")
    parser.add_argument("--sh-order", type=int, default=35)
    args = parser.parse_args()
    env = to_layout(read_hdr(Path(__file__).resolve().parents[1] / "assets" / "envmaps" / "interior.exr"), "anglemap", args.size)
    exponents = EXPONENTS[:args.maps]
    ctx = create_gl_context()
    query = ctx.query(time=True)
    middle = args.size // 2 - args.tile // 2
    tile = Tile(middle, middle, args.tile)
    print(f"{args.size}² probe and maps, {len(exponents)} maps, a {args.tile}² tile at the centre ({ctx.info['GL_RENDERER']}):")
    for name, baker in (("accurate", GLAccurateBaker(env, exponents, ctx)),
                        ("bounds", GLAccurateBaker(env, exponents, ctx, 0.03)),
                        (f"sh order {args.sh_order}", GLShBaker(env, exponents, args.sh_order, ctx))):
        baker.bake_tile(Tile(0, 0, 0))  # compiles the shaders' machine code
        ctx.finish()
        start = time.perf_counter()
        with query:
            baker.bake_tile(tile)
        ctx.finish()
        cpu = 1000 * (time.perf_counter() - start)
        gl = query.elapsed / 1e6
        terms = baker.order ** 2 if isinstance(baker, GLShBaker) else baker.inputs(tile)
        per = gl * 1e6 / (args.tile ** 2 * terms * len(exponents))
        whole = per * 1e-9 * baker.inside.sum() * len(exponents) * (
            baker.order ** 2 if isinstance(baker, GLShBaker) else
            np.mean([baker.inputs(t) for t in (tile,)]))
        print(f"  {name:14s} tile GL {gl:9.2f} ms (CPU {cpu:9.2f})   {per:7.2f} ns per texel x term x map"
              f"   whole bake ~{whole:8.1f} s of GL time")
        baker.release()


if __name__ == "__main__":
    main()
