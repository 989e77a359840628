"""Frame-budget profiling of the render loop: per frame and per step, CPU and GL time; the budget and
its misses; p50/p95/p99/max per step; a Chrome trace-event JSON (one track per step, for Perfetto and
chrome://tracing); a frame-time timeline with the budget line; profile.md with the tables; and a sweep
of tile policies like the thesis's table 6.6.

The frame time is the render thread's: steps 3-7 (steps 1-2 read the tracker's pose). The tracker, as
Vuforia's in the thesis's app, works on the camera's thread; its time is on a track of its own and out
of the budget.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arsim.core.files import atomic_path, json_text, write_text_atomic
from arsim.core.gl import TIMER_DROPPED
from arsim.render.loop import FRAME_STEPS, GL_STEPS, FrameRecord  # (the render thread's steps 3-7, PRT's relight among them)

TRACKS = ("frame",) + FRAME_STEPS + ("track",)
PERCENTILES = (50, 95, 99)


def _stats(values) -> dict:
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return {}
    return {f"p{p}": float(np.percentile(v, p)) for p in PERCENTILES} | {"max": float(v.max()), "frames": int(v.size)}


def gl_dropped(records: list[FrameRecord]) -> dict[str, dict[str, int]]:
    """Per step, the GL timer readings dropped as no time (core.gl.timer_ms), counted by why; only the steps
    with one."""
    counts: dict[str, dict[str, int]] = {}
    for r in records:
        for step, why in r.gl_dropped.items():
            counts.setdefault(step, {}).setdefault(why, 0)
            counts[step][why] += 1
    return {step: dict(sorted(c.items())) for step, c in sorted(counts.items())}


def step_gl_figures(records: list[FrameRecord]) -> dict:
    """metrics.json's GL timings: step_gl_ms, per GL step the median of its readings that are times (None, n/a,
    where the step was timed but none was), and step_gl_dropped, per step the others counted by why."""
    dropped = gl_dropped(records)
    medians = {}
    for step in GL_STEPS:
        ms = [r.gl_ms[step] for r in records if step in r.gl_ms]
        if ms or step in dropped:
            medians[step] = float(np.median(ms)) if ms else None
    return {"step_gl_ms": medians, "step_gl_dropped": dropped}


def dropped_text(dropped: dict[str, dict[str, int]], valid: dict[str, int] | None = None) -> str:
    """The dropped readings in words, e.g. "objects 2 of 120 (2 zero)"; valid: per step the readings kept."""
    parts = []
    for step, reasons in dropped.items():
        n = sum(reasons.values())
        of = f" of {n + valid.get(step, 0)}" if valid is not None else ""
        parts.append(f"{step} {n}{of} (" + ", ".join(f"{k} {why}" for why, k in reasons.items()) + ")")
    return "; ".join(parts)


@dataclass
class ProfileRun:
    """One run of the loop under one tile policy."""

    label: str  # the tile policy: a side, or auto
    method: str  # the baked maps' method
    budget_ms: float
    records: list[FrameRecord]

    def frame_ms(self) -> np.ndarray:
        return np.array([sum(r.cpu_ms.get(s, 0.0) for s in FRAME_STEPS) for r in self.records])

    def bake_end(self) -> int | None:
        """The number of frames until the bake was complete (None: it was not)."""
        return next((k + 1 for k, r in enumerate(self.records) if r.bake_done), None)

    def summary(self) -> dict:
        dropped = gl_dropped(self.records)
        frame = self.frame_ms()
        misses = int((frame > self.budget_ms).sum())
        end = self.bake_end()
        baking = frame[:end] if end else frame
        seconds = None
        if end:
            last = self.records[end - 1]
            seconds = (last.start_ms + sum(last.cpu_ms.values()) - self.records[0].start_ms) / 1000
        return {
            "policy": self.label, "method": self.method, "budget_ms": self.budget_ms, "frames": len(self.records),
            "misses": misses, "within_budget_pct": 100.0 * (1 - misses / max(len(frame), 1)),
            "frame_ms": _stats(frame),
            "bake": {"completed": end is not None, "frames_to_finish": end, "seconds": seconds,
                     "texels_done_pct": 100.0 * self.records[-1].bake_progress if self.records else 0.0,
                     "work_done_pct": 100.0 * self.records[-1].bake_work_progress if self.records else 0.0,
                     "worst_frame_ms": float(baking.max()) if baking.size else None,
                     "within_budget_pct_while_baking": 100.0 * float((baking <= self.budget_ms).mean()) if baking.size else None,
                     # (over the valid GL readings: steps["bake"]["gl_dropped"] counts the others)
                     "gl_ms_total": float(sum(r.gl_ms.get("bake", 0.0) for r in self.records))},
            "steps": {s: {"cpu": _stats([r.cpu_ms[s] for r in self.records if s in r.cpu_ms]),
                          "gl": _stats([r.gl_ms[s] for r in self.records if s in r.gl_ms]),
                          "gl_dropped": dropped.get(s, {})}
                      for s in FRAME_STEPS + ("track",)},
            "gl_dropped_why": {why: TIMER_DROPPED[why] for why in sorted({w for c in dropped.values() for w in c})},
        }

    def trace(self) -> dict:
        """Chrome trace-event JSON: complete events ("X", microseconds), a track (tid) per step."""
        events = [{"name": "process_name", "ph": "M", "pid": 1, "tid": 0, "args": {"name": f"arsim render loop ({self.label})"}}]
        events += [{"name": "thread_name", "ph": "M", "pid": 1, "tid": t, "args": {"name": name}} for t, name in enumerate(TRACKS)]
        for r in self.records:
            frame_steps = [s for s in FRAME_STEPS if s in r.cpu_ms]
            if frame_steps:
                start = r.step_start_ms[frame_steps[0]]
                events.append({"name": f"frame {r.index}", "cat": "frame", "ph": "X", "pid": 1, "tid": 0,
                               "ts": 1000 * start, "dur": 1000 * sum(r.cpu_ms[s] for s in frame_steps),
                               "args": {"budget_ms": self.budget_ms, "tag_found": r.found}})
            for s in FRAME_STEPS + ("track",):
                if s in r.cpu_ms:
                    events.append({"name": s, "cat": "step", "ph": "X", "pid": 1, "tid": TRACKS.index(s),
                                   "ts": 1000 * r.step_start_ms[s], "dur": 1000 * r.cpu_ms[s],
                                   "args": {"frame": r.index, "gl_ms": r.gl_ms.get(s)}
                                   | ({"gl_dropped": r.gl_dropped[s]} if s in r.gl_dropped else {})
                                   | ({"tiles": r.bake_tiles} if s == "bake" else {})})
        return {"traceEvents": events, "displayTimeUnit": "ms"}


def _gl_cell(ms: float) -> str:
    """A GL time in the table: below 1 µs in two significant digits (a reading of 20 ns is not one of 0)."""
    return f"{ms:.3f}" if ms >= 0.001 else f"{ms:.1e}"


def markdown(runs: list[ProfileRun]) -> str:
    """profile.md: per run the budget, the misses, the bake, and per step p50/p95/p99/max (CPU and GL)."""
    lines = ["# Render-loop profile", ""]
    for run in runs:
        s = run.summary()
        b = s["bake"]
        baking = any("bake" in r.cpu_ms for r in run.records)
        lines += [f"## Tile policy {run.label} ({run.method} maps)" if baking else f"## {run.label} ({run.method} maps, no bake)", "",
                  f"- Frames: {s['frames']}; budget {s['budget_ms']:.1f} ms; over budget: {s['misses']} "
                  f"({s['within_budget_pct']:.2f} % within)"]
        if baking:
            lines.append("- Bake: " + (f"complete after {b['frames_to_finish']} frames, {b['seconds']:.2f} s; worst frame while "
                                       f"baking {b['worst_frame_ms']:.3f} ms; {b['within_budget_pct_while_baking']:.2f} % of "
                                       f"those frames within budget; GL time {b['gl_ms_total']:.1f} ms"
                                       if b["completed"] else
                                       f"not complete: {b['texels_done_pct']:.2f} % of the texels and {b['work_done_pct']:.2f} % "
                                       f"of the work done; GL time {b['gl_ms_total']:.1f} ms")
                         + (f" (over its valid timer readings; {sum(s['steps']['bake']['gl_dropped'].values())} dropped)"
                            if s["steps"]["bake"]["gl_dropped"] else ""))
        lines += ["",
                  "| step | CPU p50 | CPU p95 | CPU p99 | CPU max | GL p50 | GL p95 | GL p99 | GL max | frames |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        rows = [("frame (steps 3-7)", s["frame_ms"], {})] + [(name, v["cpu"], v["gl"]) for name, v in s["steps"].items()]
        dropped = {name: v["gl_dropped"] for name, v in s["steps"].items() if v["gl_dropped"]}
        for name, cpu, gl in rows:
            if not cpu:
                continue
            cells = [f"{cpu[k]:.3f}" for k in ("p50", "p95", "p99", "max")]
            # n/a: the step was timed on the GL but no reading was a time
            cells += [_gl_cell(gl[k]) for k in ("p50", "p95", "p99", "max")] if gl else ["n/a"] * 4 if name in dropped else [""] * 4
            lines.append(f"| {name} | " + " | ".join(cells) + f" | {cpu['frames']} |")
        valid = {name: v["gl"].get("frames", 0) for name, v in s["steps"].items()}
        lines += ["", "Milliseconds. The frame is the render thread's steps 3-7; `track` (the tag tracker) runs on the "
                  "camera's thread, outside the budget. GL: the timer queries' readings that are times; "
                  + ("dropped as no time: " + dropped_text(dropped, valid) + "; "
                     + "; ".join(f"{why}: {text}" for why, text in s["gl_dropped_why"].items()) + "."
                     if dropped else "none dropped (every reading was a time)."), ""]
    if len(runs) > 1:
        lines += ["## Sweep (as the thesis's table 6.6)", "", sweep_table(runs), ""]
    return "\n".join(lines)


def sweep_table(runs: list[ProfileRun]) -> str:
    rows = ["| tile policy | frames to finish | total time (s) | worst frame (ms) | within budget while baking |",
            "|---|---|---|---|---|"]
    for run in runs:
        b = run.summary()["bake"]
        if b["completed"]:
            rows.append(f"| {run.label} | {b['frames_to_finish']} | {b['seconds']:.2f} | {b['worst_frame_ms']:.2f} | "
                        f"{b['within_budget_pct_while_baking']:.2f} % |")
        else:
            rows.append(f"| {run.label} | not complete | | | |")
    return "\n".join(rows)


def plot_timeline(run: ProfileRun, path: Path) -> None:
    """Frame time per frame, stacked by step, with the budget line and where the bake completed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = np.arange(len(run.records))
    fig, ax = plt.subplots(figsize=(10, 4), dpi=110)
    bottom = np.zeros(len(frames))
    for step in FRAME_STEPS:
        ms = np.array([r.cpu_ms.get(step, 0.0) for r in run.records])
        if ms.any():
            ax.fill_between(frames, bottom, bottom + ms, step="mid", label=step, linewidth=0)
            bottom += ms
    ax.axhline(run.budget_ms, color="k", linestyle="--", linewidth=1, label=f"budget {run.budget_ms:.1f} ms")
    end = run.bake_end()
    if end:
        ax.axvline(end - 1, color="tab:red", linewidth=1, label=f"bake complete (frame {end})")
    ax.set_xlabel("frame")
    ax.set_ylabel("render thread, ms")
    baking = any("bake" in r.cpu_ms for r in run.records)
    ax.set_title(f"Frame time, tile policy {run.label} ({run.method} maps)" if baking else f"Frame time, {run.label} ({run.method} maps)")
    ax.set_ylim(0, max(float(np.percentile(bottom, 99.5)) * 1.2, run.budget_ms * 1.3))
    ax.legend(loc="upper right", fontsize=8, ncol=2)
    dropped = gl_dropped(run.records)  # (the plot is CPU time; its GL readings' validity said beside it)
    fig.text(0.01, 0.01, "GL timer readings dropped as no time: " + dropped_text(dropped) if dropped else
             "GL timer readings: none dropped", fontsize=7, color="tab:red" if dropped else "0.4")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def write_profile(runs: list[ProfileRun], out_dir: Path) -> list[Path]:
    """profile.md, profile.json, and per run trace[_POLICY].json and timeline[_POLICY].png."""
    paths = []
    for run in runs:
        suffix = "" if len(runs) == 1 else f"_{run.label}"
        trace_path, plot_path = out_dir / f"trace{suffix}.json", out_dir / f"timeline{suffix}.png"
        write_text_atomic(trace_path, json.dumps(run.trace()) + "\n")
        plot_timeline(run, plot_path)
        paths += [trace_path, plot_path]
    write_text_atomic(out_dir / "profile.json", json_text({"runs": [r.summary() for r in runs]}))
    write_text_atomic(out_dir / "profile.md", markdown(runs))
    return paths + [out_dir / "profile.json", out_dir / "profile.md"]
