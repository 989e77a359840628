"""Speed of the layout conversions (prints figures; not a test).

    python benchmarks/bench_resample.py [--repeat 5]
"""

import argparse

from timing import best_of

from arsim.core.assets import assets_dir
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import supersampling_factor, to_layout

ASSET = assets_dir() / "envmaps" / "city.exr"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    eq = read_hdr(ASSET)
    am = to_layout(eq, "anglemap", 512)
    cases = [
        ("equirect 1024x512 -> angle map 512²", eq, "anglemap", 512),
        ("angle map 512² -> equirect 1024x512", am, "equirect", 512),
        ("equirect 1024x512 -> angle map 256²", eq, "anglemap", 256),
        ("equirect 1024x512 -> angle map 1024²", eq, "anglemap", 1024),
    ]
    print(f"{'conversion':<40} {'k':>2} {'best of ' + str(args.repeat):>12}")
    for name, image, layout, size in cases:
        source = "anglemap" if image.shape[0] == image.shape[1] else "equirect"
        k = supersampling_factor(source, image.shape[0], layout, size)
        seconds = best_of(args.repeat, lambda: to_layout(image, layout, size))
        print(f"{name:<40} {k:>2} {seconds * 1000:>10.1f} ms")


if __name__ == "__main__":
    main()
