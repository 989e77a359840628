"""Run every command block of README.md in order, as a new user would, in a fresh clone; time each command.

    python benchmarks/readme_examples.py                     # a fresh clone of this checkout's HEAD in a temp folder
    python benchmarks/readme_examples.py --keep /tmp/readme   # ... in that folder, kept afterwards
    python benchmarks/readme_examples.py --skip pytest        # commands matching the pattern are not run

The ```sh blocks run one after another in one bash session (so the quick start's virtual environment,
once activated, stays active), from the clone's root. Prints one row per command (block, seconds, exit
status) and writes readme_examples.json beside the clone. Exits with 1 when a command failed. About 40
minutes on 2 cores, most of it the test suite and the end-to-end runs.
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARK = "@@readme-example"


def command_blocks(readme: str) -> list[list[str]]:
    """The commands of each ```sh block: comment lines dropped, continued lines joined."""
    blocks = []
    for body in re.findall(r"^```sh\n(.*?)^```", readme, flags=re.S | re.M):
        commands, pending = [], ""
        for line in body.splitlines():
            line = pending + line
            pending = ""
            if line.rstrip().endswith("\\"):
                pending = line.rstrip()[:-1] + " "
                continue
            if line.strip() and not line.lstrip().startswith("#"):
                commands.append(line.strip())
        blocks.append(commands)
    return blocks


def session_script(blocks: list[list[str]], skip: re.Pattern | None) -> tuple[str, list[dict]]:
    """One bash script running every command, with a marker line after each: its index, status, seconds."""
    rows, lines = [], ["set +e"]
    for b, commands in enumerate(blocks, 1):
        for command in commands:
            k = len(rows)
            skipped = bool(skip and skip.search(command))
            rows.append({"block": b, "command": command, "skipped": skipped})
            if skipped:
                continue
            lines += [f"echo {shlex.quote(f'### [{b}] {command}')} >&2", "__s=$EPOCHREALTIME", command,
                      f'__rc=$?; echo "{MARK} {k} $__rc $__s $EPOCHREALTIME"']
    return "\n".join(lines) + "\n", rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     epilog="example:\n  python benchmarks/readme_examples.py --skip pytest",
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--keep", type=Path, metavar="DIR", help="clone into DIR (must not exist) and keep it")
    parser.add_argument("--skip", metavar="REGEX", help="do not run the commands that match REGEX")
    args = parser.parse_args()
    if args.keep is not None and args.keep.exists():
        print(f"readme_examples: {args.keep} exists; name a folder that does not", file=sys.stderr)
        return 2
    work = args.keep or Path(tempfile.mkdtemp(prefix="readme-examples-")) / "arsim"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(work)], check=True)
    blocks = command_blocks((work / "README.md").read_text(encoding="utf-8"))
    script, rows = session_script(blocks, re.compile(args.skip) if args.skip else None)
    start = time.perf_counter()
    done = subprocess.run(["bash", "-c", script], cwd=work, stdout=subprocess.PIPE, text=True)
    total = time.perf_counter() - start
    for line in done.stdout.splitlines():
        if line.startswith(MARK):
            _, k, rc, t0, t1 = line.split()
            rows[int(k)].update(returncode=int(rc), seconds=float(t1) - float(t0))
        else:
            print(line)
    print("\n| block | command | seconds | status |\n|---|---|---|---|")
    for r in rows:
        status = "skipped" if r["skipped"] else ("not reached" if "returncode" not in r else
                                                  "ok" if r["returncode"] == 0 else f"exit {r['returncode']}")
        seconds = f"{r['seconds']:.1f}" if "seconds" in r else ""
        print(f"| {r['block']} | `{r['command']}` | {seconds} | {status} |")
    failed = [r for r in rows if not r["skipped"] and r.get("returncode") != 0]
    print(f"\n{len(rows)} commands in {len(blocks)} blocks, {total / 60:.1f} min; "
          f"{len(failed)} failed{': ' + ', '.join(r['command'] for r in failed) if failed else ''}")
    (work.parent / "readme_examples.json").write_text(json.dumps({"total_s": total, "commands": rows}, indent=2))
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
