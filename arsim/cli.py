"""The arsim command line: parses arguments, calls the stages, prints. No pipeline logic lives here."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from arsim import __version__
from arsim.core.errors import ArsimError
from arsim.core.hdr_io import NONFINITE_POLICIES, read_hdr, replace_nonfinite, write_image
from arsim.core.image_stats import image_stats
from arsim.core.resample import LAYOUTS, detect_layout, to_layout
from arsim.scenario import DEFAULT_SCENARIO, load_scenario, scenario_to_toml

MAX_SIZE = 16384


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump) and exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _command(sub, name: str, summary: str, example: str) -> argparse.ArgumentParser:
    return sub.add_parser(
        name,
        help=summary,
        description=summary,
        epilog=f"example:\n  {example}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def _size(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r} is not an integer") from None
    if not 1 <= value <= MAX_SIZE:
        raise argparse.ArgumentTypeError(f"size {value} is out of range: give 1 to {MAX_SIZE}")
    return value


# --------------------------------------------------------------------------------------------------
# arsim info


def _fmt(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.6g}"


def cmd_info(args: argparse.Namespace) -> int:
    stats = image_stats(read_hdr(args.file))
    if args.json:
        print(json.dumps({"file": str(args.file), **stats}, indent=2))
        return 0
    kind = "angle map 1:1" if stats["layout"] == "anglemap" else "equirect 2:1"
    rows = [
        ("file", str(args.file)),
        ("size", f"{stats['width']} x {stats['height']} ({kind}, {stats['texels']} texels on the sphere)"),
        ("radiance", f"min {_fmt(stats['min'])}  max {_fmt(stats['max'])}  mean {_fmt(stats['mean'])} (finite texels, all channels)"),
        ("mean RGB", "  ".join(_fmt(v) for v in stats["mean_rgb"]) if stats["mean_rgb"] else "n/a"),
        ("sphere mean", "  ".join(_fmt(v) for v in stats["sphere_mean_rgb"]) + " (RGB, weighted by texel solid angle)"),
        ("bad texels", f"NaN {stats['nan']}  Inf {stats['inf']}  negative {stats['negative']}"),
    ]
    for key, value in rows:
        print(f"{key:<12} {value}")
    return 0


# --------------------------------------------------------------------------------------------------
# arsim convert


def cmd_convert(args: argparse.Namespace) -> int:
    if args.output.suffix.lower() not in (".exr", ".hdr", ".png"):
        raise ArsimError(f"{args.output}: unknown output type '{args.output.suffix}'; use .exr, .hdr or .png")
    image, replaced = replace_nonfinite(read_hdr(args.input), args.nan, str(args.input))
    layout = args.layout or detect_layout(image, str(args.input))
    out = to_layout(image, layout, args.size)
    write_image(args.output, out)
    if replaced:
        print(f"replaced {replaced} NaN/Inf texels with 0")
    kind = "angle map" if layout == "anglemap" else "equirect"
    print(f"wrote {args.output} ({out.shape[1]} x {out.shape[0]} {kind})")
    return 0


# --------------------------------------------------------------------------------------------------
# arsim validate


def cmd_validate(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    print(f"# {args.scenario or DEFAULT_SCENARIO}: valid; as resolved:")
    print(scenario_to_toml(scenario), end="")
    return 0


# --------------------------------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="arsim",
        description="arsim: a simulator of a mobile AR app that captures real-world light and renders virtual objects with it.",
        epilog="example:\n  arsim info assets/envmaps/city.exr\n\nrun 'arsim COMMAND --help' for the options of a command.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"arsim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    p = _command(sub, "info", "print size, layout, radiance range and bad-texel counts of an HDR image",
                 "arsim info assets/envmaps/sunrise.exr")
    p.add_argument("file", type=Path, metavar="FILE", help="OpenEXR (.exr) or Radiance (.hdr) image")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(run=cmd_info)

    p = _command(sub, "convert", "convert an HDR image between layouts, sizes and formats (.exr, .hdr, .png preview)",
                 "arsim convert assets/envmaps/city.exr city_anglemap.exr --layout anglemap --size 512")
    p.add_argument("input", type=Path, metavar="IN", help="OpenEXR (.exr) or Radiance (.hdr) image, equirect 2:1 or angle map 1:1")
    p.add_argument("output", type=Path, metavar="OUT", help=".exr (float32 RGB), .hdr, or .png (tone-mapped 8-bit preview)")
    p.add_argument("--layout", choices=LAYOUTS, help="layout of OUT (default: that of IN)")
    p.add_argument("--size", type=_size, metavar="N",
                   help="N of an N x N angle map, or the height N of a 2N x N equirect (default: the height of IN)")
    p.add_argument("--nan", choices=NONFINITE_POLICIES, default="refuse",
                   help="what to do with NaN/Inf texels: refuse the image (default) or replace them with 0")
    p.set_defaults(run=cmd_convert)

    p = _command(sub, "validate", "check a scenario file and print it as resolved (defaults filled in, paths found)",
                 "arsim validate scenarios/indoor.toml")
    p.add_argument("scenario", type=Path, nargs="?", metavar="SCENARIO", help="scenario .toml (default: the embedded default scenario)")
    p.set_defaults(run=cmd_validate)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return args.run(args)
    except ArsimError as exc:
        print(f"arsim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"arsim {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
