"""The run cache's savings (prints figures; not a test): a scenario run into a new cache (cold), again
(warm: every stage reused), and with only [render] key changed (the session and report computed); then
`arsim batch` of the scenario and two variants sharing its recording ([render] key, [render] map_size) into
a new cache, and the same batch with --no-cache (the time the cache saved). Per run: the wall time and per
stage computed or reused with its seconds (manifest.json).

    python benchmarks/bench_run_cache.py [SCENARIO] [--seed N] [--work DIR] [--skip-batch]   # default: the embedded default scenario
"""

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from arsim.scenario import load_scenario, scenario_to_toml


def run(*args) -> float:
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "arsim", *map(str, args)], capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(done.stderr)
    return time.perf_counter() - start


def stages(out: Path) -> str:
    m = json.loads((out / "manifest.json").read_text())
    # (the CPU time: the process's, all threads, without the FLIP worker's; cpu_seconds in the manifest)
    return ", ".join(f"{name} {s['status']} {s['seconds']:.1f} s (CPU {s.get('cpu_seconds', 0.0):.1f} s)"
                     for name, s in m["stages"].items())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scenario", nargs="?", help="a scenario file or bundled name (default: the embedded default)")
    parser.add_argument("--work", type=Path, help="folder for the runs and caches (default: a new temporary one)")
    parser.add_argument("--skip-batch", action="store_true", help="only the cold, warm and [render] key runs")
    parser.add_argument("--seed", type=int, help="the scenario with this [run] seed (default: its own)")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_run_cache."))
    work.mkdir(parents=True, exist_ok=True)
    s = load_scenario(args.scenario)
    if args.seed is not None:
        s = dataclasses.replace(s, run=dataclasses.replace(s.run, seed=args.seed))
    variants = {"base": s, "key": dataclasses.replace(s, render=dataclasses.replace(s.render, key=s.render.key * 1.5)),
                "size": dataclasses.replace(s, render=dataclasses.replace(s.render, map_size=s.render.map_size // 2))}
    for name, v in variants.items():
        (work / f"{name}.toml").write_text(scenario_to_toml(v))
    cache = work / "cache"
    for label, scenario in (("cold", "base"), ("warm", "base"), ("render key changed", "key")):
        out = work / label.replace(" ", "_")
        wall = run("run", work / f"{scenario}.toml", "-o", out, "--cache", cache, "--force")
        print(f"{label}: {wall:.1f} s wall; {stages(out)}")
    if args.skip_batch:
        return
    wall = run("batch", *(work / f"{n}.toml" for n in variants), "-o", work / "batch", "--cache", work / "batch_cache", "--force")
    print(f"batch of {len(variants)} sharing a recording: {wall:.1f} s wall")
    for name in variants:
        print(f"  {name}: {stages(work / 'batch' / name)}")
    alone = run("batch", *(work / f"{n}.toml" for n in variants), "-o", work / "batch_alone", "--no-cache", "--force")
    print(f"the same batch with --no-cache (every stage of every run computed): {alone:.1f} s wall; "
          f"the cache saved {alone - wall:.1f} s ({100 * (alone - wall) / alone:.0f} %)")


if __name__ == "__main__":
    main()
