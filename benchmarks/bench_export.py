"""Time `arsim export` of a default bake (the fast method, 512² angle maps, the eleven default exponents) in
every format, and of the probe alone; the files' count and size (prints figures; not a test).

    python benchmarks/bench_export.py [--env assets/envmaps/interior.exr] [--texel rgba16f]
"""

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from arsim.core.assets import assets_dir

FORMATS = "ktx2,filament,gltf,faces,equirect"


def run(*args: str, cwd: Path) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "arsim", *args], cwd=cwd, check=True)
    return time.perf_counter() - start


def size_of(folder: Path) -> tuple[int, int]:
    files = [p for p in folder.rglob("*") if p.is_file() and not p.name.startswith(".")]
    return len(files), sum(p.stat().st_size for p in files)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", type=Path, default=assets_dir() / "envmaps" / "interior.exr")
    parser.add_argument("--texel", default="rgba16f", choices=("rgba16f", "b10g11r11"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        env = args.env.resolve()
        run("bake", str(env), "-o", "maps", cwd=work)
        for name, source in (("default bake", "maps"), ("probe alone", str(env))):
            seconds = run("export", source, "-o", "engine", "--format", FORMATS, "--texel", args.texel, cwd=work)
            count, size = size_of(work / "engine")
            print(f"{name}: {seconds:.1f} s wall (with the interpreter's start), {count} files, {size / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
