"""Visual regression: two images, or the frames of two run directories matched by name, compared by FLIP
(NVIDIA's flip-evaluator, LDR), PSNR and the largest absolute difference, with a FLIP heatmap per frame
that differs and an HTML page showing them side by side.

FLIP costs most of a second on a whole 640 x 480 frame, so it is evaluated on the box around the pixels
that differ, widened beyond the reach of its filters; elsewhere the two frames are equal and FLIP is 0.
Identical frames cost a byte comparison.
"""

from __future__ import annotations

import html
import json
import math
import os
import shutil
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from arsim.core.errors import ArsimError
from arsim.core.files import json_text, write_bytes_atomic, write_text_atomic
from arsim.core.png import png_bytes, read_frame
from arsim.evaluate.flip import flip_map
from arsim.evaluate.registry import NEUTRAL, figures_of, label_of, metric_for, unit_text, worse_beyond_tolerance

IMAGE_SUFFIXES = (".png",)
DEFAULT_MAX_FLIP = 0.0  # a frame fails when its mean FLIP exceeds this: by default, any difference


@dataclass(frozen=True)
class FrameDiff:
    name: str
    flip_mean: float
    flip_p99: float
    psnr_db: float  # inf when the frames are equal
    max_abs: int  # the largest difference of an 8-bit channel
    differing_pixels: int
    heatmap: str | None = None  # relative to the diff's folder, where one was written

    def exceeds(self, max_flip: float) -> bool:
        return self.flip_mean > max_flip


@dataclass(frozen=True)
class MetricChange:
    """One figure of two runs' metrics.json (evaluate.registry): both values (None where a run lacks it), the
    change b - a, and whether b is worse beyond the figure's tolerance (gated: whether that fails the diff)."""
    path: str
    label: str
    unit: str
    better: str
    a: float | None
    b: float | None
    worse: bool
    gated: bool

    @property
    def change(self) -> float | None:
        return None if self.a is None or self.b is None else self.b - self.a

    @property
    def verdict(self) -> str:
        return ("worse" if self.gated else "worse (timed: not gated)" if self.worse else
                "only in a" if self.b is None else "only in b" if self.a is None else "")


def compare_metrics(a: dict, b: dict, gate_times: bool = False) -> list[MetricChange]:
    """Every figure of either run (figures_of), a's order first. Worse: beyond the registry's tolerance for the
    worse; timed figures (times and speeds, which differ from run to run on any machine) are listed but gate the
    diff only with gate_times."""
    fa, fb = figures_of(a), figures_of(b)
    out = []
    for path in [*fa, *(p for p in fb if p not in fa)]:
        m = metric_for(path)
        va, vb = fa.get(path), fb.get(path)
        worse = va is not None and vb is not None and worse_beyond_tolerance(m, va, vb)
        out.append(MetricChange(path, label_of(path), m.unit if m else "", m.better if m else NEUTRAL, va, vb,
                                worse, worse and (gate_times or not (m and m.timed))))
    return out


def baseline_figures(folder: Path) -> dict | None:
    """A baseline's (a run directory's, or a baseline folder's) metrics.json, or None where it has none."""
    path = Path(folder) / "metrics.json"
    if not path.is_file():
        return None
    try:
        metrics = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ArsimError(f"{path}: not readable as JSON ({e}); give a run directory written by `arsim run`") from None
    if not isinstance(metrics, dict):
        raise ArsimError(f"{path}: not a run's metrics (a JSON object); give a run directory written by `arsim run`")
    return metrics


@dataclass
class DiffResult:
    a: str
    b: str
    max_flip: float
    frames: list[FrameDiff] = field(default_factory=list)
    only_in_a: list[str] = field(default_factory=list)
    only_in_b: list[str] = field(default_factory=list)
    metrics: list[MetricChange] = field(default_factory=list)  # where both are runs with metrics.json

    @property
    def failed(self) -> list[FrameDiff]:
        return [f for f in self.frames if f.exceeds(self.max_flip)]

    @property
    def worse(self) -> list[MetricChange]:
        """The figures that got worse beyond their tolerance and gate the diff."""
        return [m for m in self.metrics if m.gated]

    @property
    def passed(self) -> bool:
        return not self.failed and not self.only_in_a and not self.only_in_b and not self.worse

    def summary(self) -> dict:
        flips = [f.flip_mean for f in self.frames]
        worst = max(self.frames, key=lambda f: f.flip_mean, default=None)
        return {
            "a": self.a, "b": self.b, "max_flip": self.max_flip, "passed": self.passed,
            "frames": len(self.frames), "frames_differing": sum(f.differing_pixels > 0 for f in self.frames),
            "frames_over_threshold": len(self.failed), "only_in_a": self.only_in_a, "only_in_b": self.only_in_b,
            "flip_mean": float(np.mean(flips)) if flips else 0.0,
            "flip_max": worst.flip_mean if worst else 0.0, "worst_frame": worst.name if worst else None,
            "per_frame": [{**asdict(f), "psnr_db": None if math.isinf(f.psnr_db) else f.psnr_db} for f in self.frames],
            "metrics_worse": [m.path for m in self.worse],
            "metrics": [asdict(m) | {"change": m.change} for m in self.metrics],
        }

    def message(self) -> str:
        """One paragraph for a terminal or a failed test: which frames, how much, where the heatmaps are."""
        lines = [f"{len(self.frames)} frames compared, {len(self.failed)} over FLIP {self.max_flip:g}"]
        for f in sorted(self.failed, key=lambda f: -f.flip_mean)[:5]:
            lines.append(f"  {f.name}: FLIP mean {f.flip_mean:.5f}, p99 {f.flip_p99:.4f}, PSNR {f.psnr_db:.1f} dB, "
                         f"max difference {f.max_abs}, {f.differing_pixels} pixels differ"
                         + (f"; heatmap {f.heatmap}" if f.heatmap else ""))
        if len(self.failed) > 5:
            lines.append(f"  ... and {len(self.failed) - 5} more")
        for side, names in (("a", self.only_in_a), ("b", self.only_in_b)):
            if names:
                lines.append(f"  {len(names)} frames only in {side} ({getattr(self, side)}), first {names[0]}")
        if self.metrics:
            lines.append(f"{len(self.metrics)} figures compared, {len(self.worse)} worse beyond their tolerance")
            for m in self.worse[:8]:
                lines.append(f"  {m.label} ({m.path}): {unit_text(metric_for(m.path), m.a)} -> {unit_text(metric_for(m.path), m.b)}")
            if len(self.worse) > 8:
                lines.append(f"  ... and {len(self.worse) - 8} more")
        return "\n".join(lines)

    def metrics_table(self) -> str:
        """Every figure as a markdown table: both values with their unit, the change, and whether it got worse."""
        rows = ["| figure | key | a | b | change | better | verdict |", "|---|---|---|---|---|---|---|"]
        for m in self.metrics:
            metric = metric_for(m.path)
            change = "" if m.change is None else f"{m.change:+.4g}"
            rows.append(f"| {m.label} | `{m.path}` | {unit_text(metric, m.a) if m.a is not None else '-'} | "
                        f"{unit_text(metric, m.b) if m.b is not None else '-'} | {change} | {m.better or '-'} | {m.verdict} |")
        return "\n".join(rows) + "\n"


def frames_of(folder: Path) -> dict[str, Path]:
    """A run directory's frames (its frames/ folder) or a folder of images, by name."""
    source = folder / "frames" if (folder / "frames").is_dir() else folder
    found = {p.name: p for p in sorted(source.iterdir()) if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()}
    if not found:
        raise ArsimError(f"{folder}: no frames (PNG files) in it or in its frames/ folder; give a run directory or a folder of frames")
    return found


def image_pairs(a: Path, b: Path) -> tuple[list[tuple[str, Path, Path]], list[str], list[str]]:
    """The frames to compare (name, a's, b's), and the names found only in a or only in b."""
    for path in (a, b):
        if not path.exists():
            raise ArsimError(f"{path}: no such file or folder; give two images or two run directories")
    if a.is_dir() != b.is_dir():
        raise ArsimError(f"{a} and {b}: one is a folder and the other a file; give two images or two run directories")
    if not a.is_dir():
        return [(b.name, a, b)], [], []
    frames_a, frames_b = frames_of(a), frames_of(b)
    common = [name for name in frames_a if name in frames_b]
    return ([(name, frames_a[name], frames_b[name]) for name in common],
            [n for n in frames_a if n not in frames_b], [n for n in frames_b if n not in frames_a])


def magma(error: np.ndarray) -> np.ndarray:
    from matplotlib import colormaps

    return (255 * colormaps["magma"](np.clip(error, 0.0, 1.0))[..., :3] + 0.5).astype(np.uint8)


def compare_images(a: np.ndarray, b: np.ndarray, name: str = "") -> tuple[FrameDiff, np.ndarray | None]:
    """The metrics of b against a (the reference), and the FLIP error map (H, W) where they differ."""
    if a.shape != b.shape:
        raise ArsimError(f"{name or 'the images'}: sizes differ ({a.shape[1]}x{a.shape[0]} against "
                         f"{b.shape[1]}x{b.shape[0]}); compare frames rendered at the same size")
    differs = (a != b).any(axis=-1)
    count = int(differs.sum())
    if count == 0:
        return FrameDiff(name, 0.0, 0.0, math.inf, 0, 0), None
    error = flip_map(a, b, differs)
    diff = a.astype(np.int16) - b.astype(np.int16)
    mse = float(np.mean(diff.astype(np.float64) ** 2))
    return (FrameDiff(name, float(error.mean()), float(np.percentile(error, 99)), 10 * math.log10(255.0 ** 2 / mse),
                      int(np.abs(diff).max()), count), error)


def check_max_flip(max_flip: float, name: str = "the FLIP limit") -> float:
    """A gate's tolerance, refused unless finite and at least 0: NaN or infinity would pass every frame."""
    if not (isinstance(max_flip, (int, float)) and math.isfinite(max_flip) and max_flip >= 0):
        raise ArsimError(f"{name} {max_flip} is not a tolerance: give a finite number from 0 (any difference fails) "
                         f"to 1, e.g. {DEFAULT_MAX_FLIP:g}")
    return float(max_flip)


def run_diff(a: Path, b: Path, out_dir: Path | None = None, max_flip: float = DEFAULT_MAX_FLIP,
             progress: Callable[[float], None] = lambda fraction: None, gate_times: bool = False) -> DiffResult:
    """Compare b against a: their frames, and where both hold a metrics.json (runs) every figure
    (compare_metrics); with out_dir, write heatmaps/<frame>.png for the frames that differ, diff.json,
    metrics.md and index.html (a, b and the heatmap side by side, the figures' table)."""
    check_max_flip(max_flip)
    pairs, only_a, only_b = image_pairs(a, b)
    result = DiffResult(str(a), str(b), max_flip, only_in_a=only_a, only_in_b=only_b)
    if a.is_dir() and b.is_dir():
        ma, mb = baseline_figures(a), baseline_figures(b)
        if ma is not None and mb is not None:
            result.metrics = compare_metrics(ma, mb, gate_times)
    if out_dir is not None:
        (out_dir / "heatmaps").mkdir(parents=True, exist_ok=True)
    for k, (name, path_a, path_b) in enumerate(pairs):
        frame, error = compare_images(read_frame(path_a), read_frame(path_b), name)
        if error is not None and out_dir is not None:
            heatmap = Path("heatmaps") / f"{Path(name).stem}.png"
            write_bytes_atomic(out_dir / heatmap, png_bytes(magma(error)))
            frame = FrameDiff(**{**asdict(frame), "heatmap": str(heatmap)})
        result.frames.append(frame)
        progress((k + 1) / len(pairs))
    if out_dir is not None:
        write_text_atomic(out_dir / "diff.json", json_text(result.summary()))
        if result.metrics:
            write_text_atomic(out_dir / "metrics.md", result.metrics_table())
        write_text_atomic(out_dir / "index.html", diff_page(result, pairs, out_dir))
    return result


def diff_page(result: DiffResult, pairs: list[tuple[str, Path, Path]], out_dir: Path) -> str:
    """The HTML page: the verdict, a table of every frame, and for each frame that differs a, b and its
    heatmap side by side (images linked from where they are)."""
    paths = {name: (pa, pb) for name, pa, pb in pairs}

    def link(path: Path) -> str:
        return html.escape(Path(os.path.relpath(path.resolve(), out_dir.resolve())).as_posix())

    verdict = "PASSED" if result.passed else "FAILED"
    rows, figures = [], []
    for f in result.frames:
        over = f.exceeds(result.max_flip)
        psnr = "∞" if math.isinf(f.psnr_db) else f"{f.psnr_db:.1f}"
        rows.append(f"<tr class=\"{'over' if over else ''}\"><td>{html.escape(f.name)}</td><td>{f.flip_mean:.5f}</td>"
                    f"<td>{f.flip_p99:.4f}</td><td>{psnr}</td><td>{f.max_abs}</td><td>{f.differing_pixels}</td></tr>")
        if f.heatmap:
            pa, pb = paths[f.name]
            figures.append(f"<h3>{html.escape(f.name)}: FLIP {f.flip_mean:.5f}</h3><div class=\"row\">"
                           f"<figure><img src=\"{link(pa)}\"><figcaption>a</figcaption></figure>"
                           f"<figure><img src=\"{link(pb)}\"><figcaption>b</figcaption></figure>"
                           f"<figure><img src=\"{html.escape(f.heatmap)}\"><figcaption>FLIP (magma: black 0, yellow 1)"
                           f"</figcaption></figure></div>")
    missing = "".join(f"<p class=\"over\">{len(names)} frames only in {side}: {html.escape(', '.join(names[:10]))}</p>"
                      for side, names in (("a", result.only_in_a), ("b", result.only_in_b)) if names)
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>arsim diff: {verdict}</title>
<style>body{{font-family:sans-serif;margin:2em}} table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;padding:2px 8px;text-align:right}}
.over{{color:#b00;font-weight:bold}} .row{{display:flex;gap:8px}} figure{{margin:0}} img{{max-width:420px}}</style></head>
<body><h1>arsim diff: {verdict}</h1>
<p>a: {html.escape(result.a)}<br>b: {html.escape(result.b)}<br>{len(result.frames)} frames compared; {len(result.failed)} with a
mean FLIP over {result.max_flip:g}; {sum(f.differing_pixels > 0 for f in result.frames)} differ at all.</p>{missing}
{metrics_html(result)}
<h2>Frames that differ</h2>{''.join(figures) or '<p>None: every frame is equal.</p>'}
<h2>Every frame</h2><table><tr><th>frame</th><th>FLIP mean</th><th>FLIP p99</th><th>PSNR (dB)</th><th>max |a-b|</th><th>pixels differing</th></tr>
{''.join(rows)}</table></body></html>
"""


def metrics_html(result: DiffResult) -> str:
    """The figures' table of the diff page (empty where the two are not runs with metrics)."""
    if not result.metrics:
        return ""
    rows = []
    for m in result.metrics:
        metric = metric_for(m.path)
        rows.append(f"<tr class=\"{'over' if m.gated else ''}\"><td style=\"text-align:left\">{html.escape(m.label)}<br><small>"
                    f"{html.escape(m.path)}</small></td><td>{html.escape(unit_text(metric, m.a)) if m.a is not None else '-'}</td>"
                    f"<td>{html.escape(unit_text(metric, m.b)) if m.b is not None else '-'}</td>"
                    f"<td>{'' if m.change is None else f'{m.change:+.4g}'}</td><td>{m.better or '-'}</td><td>{m.verdict}</td></tr>")
    return (f"<h2>Figures ({len(result.worse)} worse beyond their tolerance)</h2><table><tr><th>figure</th><th>a</th><th>b</th>"
            f"<th>change</th><th>better</th><th>verdict</th></tr>{''.join(rows)}</table>")


def update_baseline(frames: str | os.PathLike, baseline: str | os.PathLike) -> Path:
    """Make the frames the baseline: baseline/frames/ holds copies of them (replacing what was there)."""
    found = frames_of(Path(frames))
    target = Path(baseline) / "frames"
    staging = Path(baseline) / ".frames.new"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    for name, path in found.items():
        shutil.copy2(path, staging / name)
    shutil.rmtree(target, ignore_errors=True)
    staging.rename(target)  # (the old baseline is replaced whole, never left half-written)
    metrics = Path(frames) / "metrics.json"
    if metrics.is_file():  # (its figures: a run against the baseline shows them beside its own)
        write_bytes_atomic(Path(baseline) / "metrics.json", metrics.read_bytes())
    return target
