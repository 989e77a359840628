"""GL bake speed (prints figures; not a test): the accurate, bounds and SH maps baked on the GL path
(arsim/lighting/gl_bake.py), one tile in the middle of the disk after a warm-up, timed with a GL timer
query and by the time the CPU waits for it (on llvmpipe, the query can miss part of a draw spread over
its threads); per method the time of the tile and the cost per unit of work (accurate: per output
texel, input texel visited and map; bounds: per output texel, candidate and map; SH: per output texel,
SH term and map), and from it the time a whole bake would take.

    python benchmarks/bench_bake.py [--size N] [--tile T] [--maps K]
"""

import argparse
import time

import numpy as np

from arsim.core.assets import assets_dir
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.accurate import Tile, tiles
from arsim.lighting.gl_bake import GLAccurateBaker, GLShBaker

EXPONENTS = (1, 5, 10, 20, 40, 80, 160, 320, 640, 1280)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=128, help="N of the N x N probe and maps (default 128)")
    parser.add_argument("--tile", type=int, default=16, help="side of the tile timed (default 16)")
    parser.add_argument("--maps", type=int, default=8, help="maps baked at once (default 8)")
    parser.add_argument("--sh-order", type=int, default=35)
    args = parser.parse_args()
    env = to_layout(read_hdr(assets_dir() / "envmaps" / "interior.exr"), "anglemap", args.size)
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
        per = cpu * 1e6 / (args.tile ** 2 * baker.inputs(tile) * len(exponents))
        # The whole bake: every disk texel, each summing the terms its tile visits (accurate and bounds:
        # the input texels within reach of the tile, from a quarter of the disk at its centre to three
        # quarters at its rim).
        visits = np.mean([baker.inputs(t) for t in tiles(args.size, args.tile) if baker.inside[
            t.row0:t.row0 + t.size, t.col0:t.col0 + t.size].any()])
        whole = per * 1e-9 * baker.inside.sum() * len(exponents) * visits
        print(f"  {name:14s} tile {cpu:9.2f} ms (timer query {gl:9.2f})   {per:7.2f} ns per texel x term x map"
              f"   {visits:9.0f} terms per texel on average   whole bake ~{whole:8.1f} s")
        baker.release()


if __name__ == "__main__":
    main()
