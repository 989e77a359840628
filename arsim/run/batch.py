"""`arsim batch`: many scenarios run end to end, in parallel processes on this machine or as tasks on a
Ray cluster, gathered into one summary (summary.md, summary.html, summary.json) of every run's metrics
and, against baselines, its regressions.

Each scenario runs as its own `arsim run` process (its own GL context and memory; one that fails does
not take the others down) into DIR/<scenario name>. On Ray, each is a task running the same command on
a worker; the run directories are written where DIR is, so the workers must see DIR (one machine, or a
shared file system). The summary holds only what a run computes (errors, frame counts), not how long it
took, so the two backends give the same summary; wall times go to summary.json's "timing".
"""

from __future__ import annotations

import html
import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

from arsim.core.errors import ArsimError
from arsim.core.files import json_text, write_text_atomic
from arsim.core.progress import PROGRESS_ENV
from arsim.evaluate.diff import check_max_flip
from arsim.evaluate.registry import metric_for
from arsim.scenario.loader import scenario_path

# The figures a batch's summary shows (keys in the runs' metrics.json, digits); their titles and units come from
# the registry of figures (evaluate.registry), as the report's and diff's do.
COLUMNS = (
    ("session.frames_total", 0),
    ("session.frames_lost", 0),
    ("session.tracking_rot_err_deg_p95", 3),
    ("session.tracking_trans_err_pct_p95", 3),
    ("session.flip_mean", 4),
    ("capture.coverage_pct", 2),
    ("capture.orientation_rms_deg_corrected", 3),
    ("capture.irradiance_mean_err_pct", 2),
)


def column_title(key: str) -> str:
    """The figure's label with its unit, unless the label names it already ("frames lost", "AR frames' FLIP")."""
    m = metric_for(key)
    return f"{m.label} ({m.unit})" if m.unit and m.unit.split()[0] not in m.label else m.label


def _get(metrics: dict, dotted: str):
    value = metrics
    for key in dotted.split("."):
        value = value.get(key) if isinstance(value, dict) else None
    return value


def run_command(scenario: Path, out: Path, baseline: Path | None, max_flip: float, cache: str | None = None) -> list[str]:
    """cache: the run cache folder, "off" for none, None for the default."""
    command = [sys.executable, "-m", "arsim", "run", str(scenario), "-o", str(out)]
    if baseline is not None:
        command += ["--baseline", str(baseline), "--max-flip", str(max_flip)]
    if cache == "off":
        command.append("--no-cache")
    elif cache is not None:
        command += ["--cache", cache]
    return command


def run_one(scenario: str, out: str, baseline: str | None, max_flip: float, cache: str | None = None) -> dict:
    """One scenario's `arsim run` (also what a Ray task runs): its status, metrics and regression."""
    start, started = time.perf_counter(), time.time()
    done = subprocess.run(run_command(Path(scenario), Path(out), Path(baseline) if baseline else None, max_flip, cache),
                          # (its stderr is kept for its last line, the error: its progress lines would go nowhere)
                          capture_output=True, text=True, env=os.environ | {"PYTHONUNBUFFERED": "1", PROGRESS_ENV: "off"})
    result = {"scenario": scenario, "out": out, "returncode": done.returncode, "wall_s": time.perf_counter() - start}

    def written(path: Path) -> bool:  # by this run: a file left by an earlier run into the folder does not count
        return path.is_file() and path.stat().st_mtime >= started

    manifest, diff = Path(out) / "manifest.json", Path(out) / "diff" / "diff.json"
    if written(manifest):
        m = json.loads(manifest.read_text(encoding="utf-8"))
        result["metrics"] = m["metrics"]
        result["stages"] = {name: s["status"] for name, s in m.get("stages", {}).items()}
    if baseline is not None and written(diff):
        d = json.loads(diff.read_text(encoding="utf-8"))
        result["regression"] = {"passed": d["passed"], "flip_max": d["flip_max"], "worst_frame": d["worst_frame"],
                                "frames_over_threshold": d["frames_over_threshold"]}
    # exit 1 is a regression only where the run wrote its manifest and a failing diff; any other status
    # (a crash also exits 1) is a failed run
    regressed = "metrics" in result and not result.get("regression", {}).get("passed", True)
    result["ok"] = done.returncode == 0 or (done.returncode == 1 and regressed)
    lines = done.stderr.strip().splitlines()
    result["error"] = None if result["ok"] else (lines[-1] if lines else f"exit status {done.returncode}")
    return result


def check_ray_address(address: str, timeout_s: float = 3.0) -> None:
    """ArsimError in one line unless a Ray head answers at address (host:port, or auto)."""
    if address == "auto":
        return  # ray.init finds the local head, or says there is none
    host, _, port = address.removeprefix("ray://").rpartition(":")
    try:
        with socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout_s):
            pass
    except (OSError, ValueError):
        raise ArsimError(f"no Ray head answers at {address}; start one (ray start --head) and give its address, "
                         "e.g. 127.0.0.1:6379, or auto") from None


def _run_local(jobs: list[tuple], workers: int, done: Callable[[dict], None]) -> list[dict]:
    results = []
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for future in as_completed([pool.submit(run_one, *job) for job in jobs]):
            results.append(future.result())
            done(results[-1])
    return results


def _run_ray(jobs: list[tuple], address: str, done: Callable[[dict], None]) -> list[dict]:
    try:
        import ray
    except ImportError:
        raise ArsimError("--ray needs the ray package: pip install 'arsim[ray]'") from None
    check_ray_address(address)
    try:
        ray.init(address=address, logging_level="ERROR", log_to_driver=False)
    except (ConnectionError, RuntimeError) as exc:
        raise ArsimError(f"cannot join the Ray cluster at {address}: {str(exc).splitlines()[0]}") from None
    try:
        task = ray.remote(num_cpus=1)(run_one)
        pending = {task.remote(*job): job for job in jobs}
        results = []
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            pending.pop(ready[0])
            results.append(ray.get(ready[0]))
            done(results[-1])
        return results
    finally:
        ray.shutdown()


def run_batch(scenarios: list[Path], out: Path, workers: int = 1, ray_address: str | None = None,
              baselines: Path | None = None, max_flip: float = 0.0, done: Callable[[dict], None] = lambda r: None,
              cache: Path | None = None, no_cache: bool = False) -> dict:
    """Run every scenario into out/<name>, then write the summary; returns it. The runs share the run cache
    (README: The run cache; cache: its folder, else the default): scenarios with the same recording (or
    capture, maps...) compute it once, runs at once waiting on the first."""
    scenarios = [scenario_path(s) for s in scenarios]  # bundled names to their files
    names = [s.stem for s in scenarios]
    if len(set(names)) != len(names):
        raise ArsimError("two scenarios have the same file name; their runs would share a folder: rename one")
    max_flip = check_max_flip(max_flip, "the batch's FLIP limit")
    jobs = [(str(s.resolve()), str((out / s.stem).resolve()),
             str((baselines / s.stem).resolve()) if baselines is not None else None, max_flip,
             "off" if no_cache else (str(cache.resolve()) if cache is not None else None)) for s in scenarios]
    start = time.perf_counter()
    results = _run_ray(jobs, ray_address, done) if ray_address else _run_local(jobs, workers, done)
    wall = time.perf_counter() - start
    order = {str(Path(j[0])): k for k, j in enumerate(jobs)}
    results.sort(key=lambda r: order[r["scenario"]])
    summary = {"scenarios": [{**{k: v for k, v in r.items() if k not in ("wall_s", "out", "stages")}, "name": Path(r["scenario"]).stem}
                             for r in results],
               "failed": [Path(r["scenario"]).stem for r in results if not r["ok"]],
               "regressions": [Path(r["scenario"]).stem for r in results if not r.get("regression", {}).get("passed", True)]}
    write_text_atomic(out / "summary.md", summary_markdown(summary))
    write_text_atomic(out / "summary.html", summary_html(summary))
    timing = {"backend": f"ray {ray_address}" if ray_address else f"local, {workers} workers", "wall_s": wall,
              "per_scenario_s": {Path(r["scenario"]).stem: r["wall_s"] for r in results},
              # (which stages each run reused from the cache: how long they took depends on it)
              "stages": {Path(r["scenario"]).stem: r.get("stages", {}) for r in results}}
    write_text_atomic(out / "summary.json", json_text(summary | {"timing": timing}))
    return summary | {"timing": timing}


def _cell(value, digits: int) -> str:
    if value is None:
        return "n/a"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def _rows(summary: dict) -> tuple[list[str], list[list[str]]]:
    header = ["scenario", "status"] + [column_title(key) for key, _ in COLUMNS] + ["against baseline"]
    rows = []
    for s in summary["scenarios"]:
        status = "ok" if s["ok"] else f"failed: {s['error']}"
        reg = s.get("regression")
        against = "n/a" if reg is None else ("passed" if reg["passed"] else
                                              f"REGRESSION: FLIP {reg['flip_max']:.5f} ({reg['worst_frame']})")
        rows.append([s["name"], status] + [_cell(_get(s.get("metrics", {}), key), d) for key, d in COLUMNS] + [against])
    return header, rows


def summary_markdown(summary: dict) -> str:
    header, rows = _rows(summary)
    lines = ["# Batch summary", "", f"{len(rows)} scenarios; failed: {', '.join(summary['failed']) or 'none'}; "
             f"regressions: {', '.join(summary['regressions']) or 'none'}.", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def summary_html(summary: dict) -> str:
    header, rows = _rows(summary)
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(
        f"<td><a href=\"{html.escape(c)}/report/index.html\">{html.escape(c)}</a></td>" if k == 0 else
        f"<td class=\"{'bad' if c.startswith(('failed', 'REGRESSION')) else ''}\">{html.escape(c)}</td>"
        for k, c in enumerate(row)) + "</tr>" for row in rows)
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>arsim batch summary</title>
<style>body{{font-family:sans-serif;margin:2em}} table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;padding:2px 8px}}
.bad{{color:#b00;font-weight:bold}}</style></head><body><h1>Batch summary</h1>
<p>{len(rows)} scenarios; failed: {html.escape(', '.join(summary['failed']) or 'none')}; regressions:
{html.escape(', '.join(summary['regressions']) or 'none')}. Each scenario's name links to its report.</p>
<table><tr>{head}</tr>{body}</table></body></html>
"""
