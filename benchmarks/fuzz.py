"""The long fuzz profile: scenarios drawn from the schema, recordings damaged file by file, damaged HDR
files, `arsim bake` option combinations and the options of every other command, each run through arsim
as a user would meet it; prints how many inputs were tried, how many loaded or were refused, and every
one that escaped with a traceback, printed more than one line (a C library's lines on fd 2 counted),
left output behind after a refusal, hung past 60 s, or passed 2 GiB of memory. tests/test_fuzz.py runs
the same strategies on a small budget.

    python benchmarks/fuzz.py                      # 20,000 scenarios, 2,000 recordings, 2,000 HDR files,
                                                   # 2,000 bake option sets, 2,000 command lines
    python benchmarks/fuzz.py --scale 0.1          # a tenth of each
    python benchmarks/fuzz.py --only scenarios     # one family

Writes benchmarks/results/fuzz.json (counts, failures, seconds, peak memory).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import resource
import shutil
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hypothesis import HealthCheck, given, settings  # noqa: E402

from arsim.core.errors import ArsimError  # noqa: E402
from arsim.scenario.loader import parse_scenario  # noqa: E402
from tests.fuzzing import (bake_options, check_command, command_options, hdr_files, prepare_inputs,  # noqa: E402
                           quiet_outcome, recording_mutations, scenario_texts)

HANG_S = 60.0
MEMORY_LIMIT = 2 << 30
FAMILIES = {"scenarios": 20000, "recordings": 2000, "images": 2000, "options": 2000, "commands": 2000}


class Tally:
    def __init__(self, family: str):
        self.family, self.tried, self.ok, self.refused, self.failures, self.slowest = family, 0, 0, 0, [], 0.0

    @contextlib.contextmanager
    def case(self, what):
        start = time.perf_counter()
        self.tried += 1
        try:
            yield self
        except Exception as exc:  # a traceback a user would have seen
            self.failures.append({"input": str(what)[:300], "error": "".join(traceback.format_exception_only(exc)).strip()[:300]})
        seconds = time.perf_counter() - start
        self.slowest = max(self.slowest, seconds)
        if seconds > HANG_S:
            self.failures.append({"input": str(what)[:300], "error": f"took {seconds:.0f} s (over {HANG_S:.0f} s)"})

    def summary(self) -> dict:
        return {"tried": self.tried, "loaded": self.ok, "refused": self.refused, "failures": self.failures,
                "slowest_s": round(self.slowest, 2)}


def fuzz_scenarios(n: int, tally: Tally) -> None:
    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(scenario_texts())
    def run(text):
        with tally.case(text):
            try:
                parse_scenario(text, "fuzz.toml")
                tally.ok += 1
            except ArsimError as exc:
                if "\n" in str(exc).strip():
                    raise AssertionError(f"a refusal of {len(str(exc).splitlines())} lines") from None
                tally.refused += 1
    run()


def _count(tally: Tally, result: str, err: list[str]) -> None:
    if result in ("ok", "reached work"):
        tally.ok += 1
    elif len(err) != 1:
        raise AssertionError(f"a refusal of {len(err)} lines: {err[:3]}")
    else:
        tally.refused += 1


def fuzz_recordings(n: int, tally: Tally, work: Path) -> None:
    inputs = prepare_inputs(work / "inputs")

    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(recording_mutations())
    def run(mutate):
        rec = work / "mutated"
        shutil.rmtree(rec, ignore_errors=True)
        shutil.copytree(inputs["rec"], rec, ignore=shutil.ignore_patterns("plots"))
        what = mutate(rec)
        with tally.case(what):
            _count(tally, *quiet_outcome(["info", str(rec)]))
    run()


def fuzz_images(n: int, tally: Tally, work: Path) -> None:
    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(hdr_files())
    def run(file):
        suffix, data = file
        path = work / f"f{suffix}"
        path.write_bytes(data)
        with tally.case(data[:120]):
            _count(tally, *quiet_outcome(["info", str(path)]))
    run()


def fuzz_commands(n: int, tally: Tally, work: Path) -> None:
    inputs = prepare_inputs(work / "inputs")

    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(command_options(inputs))
    def run(argv):
        out = work / "out"
        shutil.rmtree(out, ignore_errors=True)
        with tally.case(argv):
            result = check_command(argv, out)  # (a refusal of more than one line, or leaving output, raises)
            tally.ok += result != "refused"
            tally.refused += result == "refused"
    run()


def fuzz_options(n: int, tally: Tally, work: Path) -> None:
    env = ROOT / "assets" / "envmaps" / "courtyard.exr"

    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(bake_options())
    def run(options):
        out = work / "maps"
        shutil.rmtree(out, ignore_errors=True)
        with tally.case(options):
            result, err = quiet_outcome(["bake", str(env), "-o", str(out), "--size", "16", *options])
            if result == "refused" and out.exists():
                raise AssertionError("a refusal left its output folder")
            _count(tally, result, err)
    run()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="example:\n  python benchmarks/fuzz.py --scale 0.1")
    parser.add_argument("--scale", type=float, default=1.0, help="fraction of each family's inputs (default 1)")
    parser.add_argument("--only", choices=sorted(FAMILIES), action="append", help="run only these families")
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "fuzz.json")
    args = parser.parse_args()
    results, start = {}, time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for family in args.only or FAMILIES:
            n = max(1, round(FAMILIES[family] * args.scale))
            tally, t0 = Tally(family), time.perf_counter()
            work = Path(tmp) / family
            work.mkdir()
            if family == "scenarios":
                fuzz_scenarios(n, tally)
            else:
                {"recordings": fuzz_recordings, "images": fuzz_images, "options": fuzz_options,
                 "commands": fuzz_commands}[family](n, tally, work)
            results[family] = tally.summary() | {"seconds": round(time.perf_counter() - t0, 1)}
            r = results[family]
            print(f"{family:<11} {r['tried']:>6} tried, {r['loaded']:>6} loaded, {r['refused']:>6} refused, "
                  f"{len(r['failures'])} failures, slowest {r['slowest_s']:.1f} s, {r['seconds']:.0f} s", flush=True)
            for f in r["failures"][:10]:
                print(f"    {f['error']}  <- {f['input'][:120]!r}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    summary = {"families": results, "peak_memory_bytes": peak, "seconds": round(time.perf_counter() - start, 1)}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(summary, indent=2) + "\n")
    print(f"peak memory {peak / 2**30:.2f} GiB (limit {MEMORY_LIMIT / 2**30:.0f}); {summary['seconds']:.0f} s; {args.json}")
    failed = any(r["failures"] for r in results.values()) or peak > MEMORY_LIMIT
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
