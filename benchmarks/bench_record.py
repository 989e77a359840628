"""Time `arsim record` of the capture sweep (prints figures; not a test).

    python benchmarks/bench_record.py [--scenario FILE] [--with-ar] [--repeat 2]

Runs the command line as a user would (plots included) in a fresh process per run, on the default
scenario with the AR path switched off unless --with-ar: the sweep is 60 s at 30 fps, 640 x 480.
Prints each run's wall time, the CPU time it used (user + system, all threads) and the CPU time the
machine's host took away meanwhile (steal, from /proc/stat: on a shared virtual machine the same run
varies by a third with it), then the median.
"""

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _steal_s() -> float:
    """CPU time stolen by the hypervisor so far, all CPUs (0 where /proc/stat is not there)."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", type=Path, help="scenario file (default: the embedded default)")
    parser.add_argument("--with-ar", action="store_true", help="keep the AR path the scenario asks for")
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scenario = args.scenario
        if not args.with_ar:
            text = scenario.read_text() if scenario else ""
            scenario = Path(tmp) / "sweep.toml"
            scenario.write_text(text + ("\n[ar]\nenabled = false\n" if "[ar]" not in text else ""))
            if "[ar]" in text:
                sys.exit("--scenario has an [ar] section: set enabled = false in it, or pass --with-ar")
        walls = []
        for k in range(args.repeat):
            out = Path(tmp) / f"rec{k}"
            command = [sys.executable, "-m", "arsim.cli", "record", "-o", str(out)] + ([str(scenario)] if scenario else [])
            start, cpu, steal = time.perf_counter(), _children_cpu_s(), _steal_s()
            done = subprocess.run(command, capture_output=True, text=True)
            seconds = time.perf_counter() - start
            cpu, steal = _children_cpu_s() - cpu, _steal_s() - steal
            if done.returncode:
                sys.exit(done.stderr)
            frames = len(list((out / "frames").glob("*.png")))
            walls.append(seconds)
            print(f"run {k + 1}: {seconds:.1f} s for {frames} frames ({1000 * seconds / frames:.1f} ms per frame, "
                  f"everything included); {cpu:.1f} s CPU, {steal:.1f} s stolen")
        print(f"median {statistics.median(walls):.1f} s, range {min(walls):.1f}-{max(walls):.1f} s over {len(walls)} runs")


if __name__ == "__main__":
    main()
