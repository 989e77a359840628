"""The run's report: one self-contained HTML page (report/index.html, images embedded). It opens with the
verdicts (a headline figure per stage against the scenario's [report] thresholds, evaluate.registry) and links to
the run's other files; then the captured probe beside the truth, the maps beside the truth's and their error, the
AR frames beside their truth frames and FLIP maps, every figure with its unit and meaning, and the drift,
tracking and frame-time plots; the scenario last."""

from __future__ import annotations

import base64
import html
import math
import re
from pathlib import Path

import numpy as np

from arsim.core.files import atomic_path, write_text_atomic
from arsim.core.png import png_bytes, read_frame
from arsim.evaluate.diff import compare_images, magma
from arsim.evaluate.registry import figures_of, label_of, metric_for, unit_text, verdicts, worse_beyond_tolerance
from arsim.evaluate.tracking import TrackingRun
from arsim.lighting.mapset import MapSet
from arsim.scenario.loader import scenario_to_toml
from arsim.scenario.sections import Scenario


def _img(path: Path, alt: str, width: int | None = None) -> str:
    if not path.is_file():
        return f"<p>({html.escape(alt)}: not written)</p>"
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    size = f' style="max-width:{width}px"' if width else ""
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}"{size}>'


def _num(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def _table(header: list[str], rows: list[list], escape: bool = True, cls: str = "") -> str:
    """rows' cells are HTML already (escape: the header is escaped)."""
    head = "".join(f"<th>{html.escape(h) if escape else h}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table{f' class={chr(34)}{cls}{chr(34)}' if cls else ''}><tr>{head}</tr>{body}</table>"


def plot_tracking(t: TrackingRun, frames: np.ndarray, path: Path) -> None:
    """Rotation and position error of the tracked tag per frame; where the tag was lost."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(2, 1, figsize=(9, 4.5), dpi=100, sharex=True)
    lost = ~t.found
    for ax, values, label in ((a, t.rot_err_deg, "rotation error (degrees)"), (b, t.trans_err_pct, "position error (% of distance)")):
        shown = np.where(np.isfinite(values), values, np.nan)
        ax.plot(frames, shown, linewidth=0.8)
        ax.set_ylabel(label, fontsize=8)
        if lost.any():
            top = np.nanmax(shown) if np.isfinite(shown).any() else 1.0
            ax.fill_between(frames, 0, top, where=lost, color="tab:red", alpha=0.15, step="mid", label="tag lost")
            ax.legend(fontsize=8, loc="upper right")
    b.set_xlabel("frame of the AR path")
    fig.suptitle("The tracked tag's pose against the truth, per frame (shaded: the tag lost, nothing drawn)", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


ESTIMATE_COLUMNS = (("sh_error", "SH error, % of the truth's", 100, 1), ("main_light_error_deg", "main light, degrees off", 1, 1),
                    ("main_light_intensity_ratio", "main light intensity, x truth", 1, 2), ("ambient_ratio", "ambient, x truth", 1, 2),
                    ("diffuse_sphere_rmse", "diffuse sphere RMSE, %", 100, 1), ("mirror_sphere_hdr_flip", "mirror sphere HDR-FLIP", 1, 3),
                    ("converged_at_frame", "converged at frame", 1, 0), ("stability", "change a frame, %", 100, 2),
                    ("ar_flip_mean", "AR objects' FLIP vs truth frame", 1, 4))


def _why(reason: str) -> str:
    """metrics.json's "truth" reason without its "absent: " (the report's sentences say it)."""
    return reason.removeprefix("absent: ")


def _absent(why: str) -> str:
    """A section's note on what it leaves out, and why (metrics.json's "truth")."""
    return f'<p class="absent">Left out: {html.escape(_why(why))}.</p>'


def _estimates_section(out: Path, estimates: dict, absent: str | None = None) -> str:
    """The light estimates: their scores at the sweep's end, the spheres, the scores over the sweep and the AR
    objects lit by each estimate beside the truth frame. absent: why they are not scored (no true environment):
    then the spheres and the AR objects lit by each estimate alone."""
    folder = out / "estimates"
    frames = "".join(f"<figure>{_img(f, f.name)}<figcaption>AR frame {int(f.stem)}</figcaption></figure>"
                     for f in sorted((folder / "frames").glob("*.png")))
    if absent is not None:
        return f"""<h2 id="estimates">Light estimates as phones report them</h2>
<p>What ARCore, ARKit and WebXR give an app instead of a probe, estimated over the sweep by the capture (from its
probe as it grew) and from each frame alone (<code>single</code>): every frame's estimates in
estimates/estimates.jsonl, the platforms' structures in estimates/platforms/.</p>
{_absent("the estimates' scores (" + _why(absent) + ")")}
<h3>The three spheres (diffuse, matte silver, mirror), lit by each estimate</h3>
{_img(folder / 'spheres.png', 'spheres', 400)}
<h3>The AR objects lit by each estimate</h3>
<div class="row">{frames}</div>
"""
    if not estimates:
        return ""
    rows = [[name] + ["n/a" if e.get(key) is None else _num(e[key] * scale, digits) for key, _, scale, digits in ESTIMATE_COLUMNS]
            for name, e in estimates.items()]
    return f"""<h2 id="estimates">Light estimates as phones report them</h2>
<p>What ARCore, ARKit and WebXR give an app instead of a probe (SH of the radiance, a main light, a 16 x 16 cubemap,
an ambient intensity), estimated over the sweep by the capture (from its probe as it grew) and from each frame alone
(<code>single</code>), scored against the truth's own estimate at the sweep's end (estimates/scores.json; every frame's
estimates in estimates/estimates.jsonl, the platforms' structures in estimates/platforms/). The AR objects are lit by each
estimate as a renderer lights with it: the SH ambient and the main light as a directional light for diffuse, the
cubemap for reflections.</p>
{_table(['estimator'] + [label for _, label, _, _ in ESTIMATE_COLUMNS], rows)}
<h3>The three spheres (diffuse, matte silver, mirror), lit by each estimate and by the truth</h3>
{_img(folder / 'spheres.png', 'spheres', 400)}
<h3>Scores over the sweep</h3>{_img(folder / 'scores.png', 'scores over the sweep', 900)}
<h3>The AR objects lit by each estimate, beside the truth frame (FLIP over the objects below)</h3>
<div class="row">{frames}</div>
"""


PAGE_WIDTH = 1400  # pixels: the widest image the report embeds at full size


def frame_vs_truth(frame: Path, truth: Path, path: Path) -> float | None:
    """The frame, its truth frame and the FLIP map between them side by side (magma, with a colour bar drawn
    beside it, its top written on it); returns the FLIP mean over the frame (None: the frames are equal)."""
    import cv2

    a, b = read_frame(truth), read_frame(frame)
    diff, error = compare_images(a, b, frame.name)
    error = error if error is not None else np.zeros(a.shape[:2], np.float32)
    # FLIP's range is 0-1, but the objects' errors are often a few hundredths: the scale's top is the larger of
    # 0.05 and the 99.9th percentile of the pixels that differ, written on the colour bar
    differs = error > 0
    top = max(0.05, float(np.percentile(error[differs], 99.9))) if differs.any() else 1.0
    heat = magma(error / top)
    bar = np.repeat(magma(np.linspace(1, 0, a.shape[0])[:, None].astype(np.float32)), 12, axis=1)
    labels = np.concatenate([bar, np.full((a.shape[0], 40, 3), 255, np.uint8)], axis=1)
    for value, y in ((top, 12), (top / 2, a.shape[0] // 2), (0.0, a.shape[0] - 4)):
        cv2.putText(labels, f"{value:.2g}", (14, y), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    gap = np.full((a.shape[0], 6, 3), 255, np.uint8)
    write = np.concatenate([b, gap, a, gap, heat, gap, labels], axis=1)
    if write.shape[1] > PAGE_WIDTH:  # (sized for the page: the report embeds it)
        write = cv2.resize(write, (PAGE_WIDTH, round(write.shape[0] * PAGE_WIDTH / write.shape[1])), interpolation=cv2.INTER_AREA)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(png_bytes(write))
    return diff.flip_mean if error is not None else None


def _verdict_section(metrics: dict, scenario: Scenario, baseline: dict | None) -> str:
    """The verdict table: per stage its headline figure, unit, what it measures, the thresholds and pass/warn/fail;
    with a baseline run's metrics, its value and the change beside."""
    rows = []
    theirs = verdicts(baseline, scenario.render.method, scenario.report) if baseline is not None else []
    for v in verdicts(metrics, scenario.render.method, scenario.report):
        status = v.status
        value = unit_text(v.metric, v.value) if v.value is not None else "n/a"
        cells = [html.escape(v.stage), f'<span class="{status.replace("/", "")}">{status}</span>', html.escape(value),
                 html.escape(label_of(v.path) if v.value is not None else v.metric.label) + f'<br><small>{html.escape(v.metric.meaning)}'
                 + (f"; {html.escape(v.note)}" if v.note else "") + "</small>", html.escape(v.threshold_text())]
        if baseline is not None:
            b = next((x for x in theirs if x.metric == v.metric), None)
            if b is None or b.value is None or v.value is None:
                cells += ["n/a", ""]
            else:
                worse = worse_beyond_tolerance(v.metric, b.value, v.value)
                cells += [html.escape(unit_text(v.metric, b.value)),
                          f'<span class="{"fail" if worse else ""}">{v.value - b.value:+.4g}{" (worse)" if worse else ""}</span>']
        rows.append(cells)
    header = ["stage", "verdict", "value", "figure", "thresholds ([report])"] + (["baseline", "change"] if baseline is not None else [])
    counts = {k: sum(r[1].count(f">{k}<") for r in rows) for k in ("pass", "warn", "fail", "n/a")}
    overall = "fail" if counts["fail"] else "warn" if counts["warn"] else "pass"
    return (f'<h2 id="summary">Summary: <span class="{overall}">{overall}</span></h2>'
            f"<p>{counts['pass']} pass, {counts['warn']} warn, {counts['fail']} fail, {counts['n/a']} not judged. Thresholds "
            "come from the scenario's <code>[report]</code> section (README: Reading a run); each figure is defined "
            "in the tables below.</p>" + _table(header, rows, escape=False, cls="verdicts"))


def _figures_table(metrics: dict, prefix: str, skip: tuple[str, ...] = ()) -> str:
    """Every figure under prefix with its label, value and unit, and meaning (evaluate.registry); its key small."""
    rows = []
    for path, value in figures_of({prefix: metrics.get(prefix, {})}).items():
        if any(path.startswith(f"{prefix}.{k}") for k in skip):
            continue
        m = metric_for(path)
        rows.append([html.escape(label_of(path)), html.escape(unit_text(m, value)),
                     html.escape(m.meaning if m else ""), f"<small><code>{html.escape(path)}</code></small>"])
    return _table(["figure", "value", "what it measures", "key in metrics.json"], rows, escape=False, cls="figures")


def _links(out: Path) -> str:
    names = [("session.mp4", "the AR session's video"), ("profile/profile.md", "frame-time profile"),
             ("profile/trace.json", "trace (chrome://tracing, Perfetto)"), ("metrics.json", "every figure"),
             ("manifest.json", "files, stages, versions"), ("scenario.toml", "the scenario as run")]
    return "<p class=\"links\">" + " · ".join(f'<a href="../{n}">{html.escape(label)}</a>' for n, label in names
                                             if (out / n).is_file() or n == "manifest.json") + "</p>"


def _shown_toml(scenario: Scenario) -> str:
    """The scenario's TOML with absolute paths shortened to their names (the run's scenario.toml has them whole)."""
    return re.sub(r'"(/[^"]*/)([^"/]+)"', r'".../\2"', scenario_to_toml(scenario))


def write_report(out: Path, scenario: Scenario, source: str, metrics: dict, tracking: TrackingRun, frames: np.ndarray,
                 maps: dict[str, MapSet], truth_maps: dict[str, MapSet] | None = None, baseline: dict | None = None) -> Path:
    """report/index.html. Where the recording lacks a truth (metrics["truth"]), each section that needs it says
    what it leaves out and why instead. truth_maps: the true environment's maps (shown beside the maps); baseline:
    a baseline run's metrics.json (its figures beside this run's in the summary)."""
    report = out / "report"
    report.mkdir(exist_ok=True)
    absent = metrics.get("truth", {})
    no_poses, no_scene = absent.get("groundtruth"), absent.get("scenario")
    # (the maps' figures are drawn by the maps stage, maps_figures: a run that reuses the maps reuses them)
    compared = [name for name in maps if truth_maps and name in truth_maps]  # [render] method's first
    compared.sort(key=lambda name: name != scenario.render.method)
    if tracking.measured:
        plot_tracking(tracking, frames, report / "tracking.png")
    s = metrics["session"]
    by_construction = bool(s.get("lit_by_truth"))
    shown = sorted((out / "frames").glob("*.png"))
    flip_of = dict(zip((int(k) for k in s["frames_rendered"]), s.get("flip_per_frame", [])))
    figures = []
    for f in shown:
        truth_frame = out / "frames" / "truth" / f.name
        flip = flip_of.get(int(f.stem))
        caption = f"frame {int(f.stem)}"
        if not no_scene:
            caption += ": FLIP " + (_num(flip, 4) if flip is not None else "n/a (no object drawn)")
        if truth_frame.is_file():
            frame_vs_truth(f, truth_frame, report / f"frame_{f.stem}.png")
            figures.append(f"<figure>{_img(report / f'frame_{f.stem}.png', f.name, 1100)}<figcaption>{caption}; "
                           "left to right: the frame, its truth frame, the FLIP map (magma, black 0; the colour bar's top is written "
                           "on it)</figcaption></figure>")
        else:
            figures.append(f"<figure>{_img(f, f.name, 420)}<figcaption>{caption}</figcaption></figure>")
    lost = s.get("frames_lost", 0)
    estimates = _estimates_section(out, metrics.get("estimates", {}), no_scene)
    scored = ("the frames are not scored: " + html.escape(_why(no_scene)) if no_scene else
              f"FLIP against the truth frame {_num(s.get('flip_mean'), 4)}, the mean over {s.get('flip_frames')} frames "
              f"({'every' if scenario.render.flip_every == 1 else f'every {scenario.render.flip_every}th'} frame with "
              "objects, and the frames shown), over the objects' mask, the truth frame drawn at the tracked pose: it "
              "measures the light, not the tracking"
              + (" (<b>0 by construction here</b>: the objects were lit by the true environment's own maps)" if by_construction else ""))
    if no_scene:
        probe = f"""<h2 id="capture">Captured probe</h2>{_absent("the true environment beside it (" + _why(no_scene) + ")")}
{_img(out / 'capture' / 'probe.png', 'captured probe', 500)}"""
    else:
        probe = f"""<h2 id="capture">Captured probe and the truth</h2>{_img(out / 'capture' / 'probe_vs_truth.png', 'probe vs truth', 1100)}"""
    map_rows = []
    for name, m in metrics["maps"].items():
        for exp, e in m.get("per_exponent", {}).items():
            own = ("0 (by construction: the reference itself)" if name == "accurate"
                   else _num(e["method_error_on_truth_pct"], 2))
            map_rows.append([name, "irradiance" if exp == "1" else f"s = {exp}", _num(e["error_vs_truth_same_method_pct"], 2),
                             _num(e["error_vs_truth_accurate_pct"], 2), own])
    if no_scene:
        maps_table = _absent("the maps' errors (" + _why(no_scene) + ")")
    else:
        maps_table = f"""<p>Mean relative error per texel, %: against the same method on the true environment (what the capture
costs), against the true environment's exact (accurate) maps (capture and method together), and the method's own
error on the true environment. Accurate and bounds maps are baked on the GL path (float32, held to the NumPy float64
sums within 1e-3 by the tests).</p>
{_table(['method', 'map', 'vs truth, same method (%)', 'vs truth, accurate (%)', 'method on truth (%)'], map_rows)}
{''.join(_img(out / 'maps' / f'vs_truth_{name}.png', f'{name} maps against the truth', 1100) for name in compared)}"""
    truth_note = "".join(f"<li>{html.escape(_why(why))}</li>" for why in absent.values())
    page = f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>arsim run: {html.escape(scenario.run.name)}</title>
<style>body{{font-family:sans-serif;margin:1.5em 2em;max-width:1200px}} table{{border-collapse:collapse;margin:0.5em 0}}
td,th{{border:1px solid #ccc;padding:2px 8px;vertical-align:top}} td{{text-align:right}} td:first-child{{text-align:left}}
td small{{color:#555}} .row{{display:flex;gap:8px;flex-wrap:wrap}} figure{{margin:0 0 0.8em 0}} img{{max-width:100%}}
pre{{background:#f4f4f4;padding:8px;max-height:300px;overflow:auto}} nav a{{margin-right:1em}} .absent{{color:#8a5a00}}
.pass{{color:#fff;background:#2a7d2a;padding:0 6px;border-radius:3px}} .warn{{color:#000;background:#f0c000;padding:0 6px;border-radius:3px}}
.fail{{color:#fff;background:#c0392b;padding:0 6px;border-radius:3px}} .na{{color:#555}} .links a{{margin-right:0.3em}}
table.verdicts td:nth-child(4), table.figures td:nth-child(3), table.figures td:nth-child(4){{text-align:left}}</style></head>
<body><h1>arsim run: {html.escape(scenario.run.name)}</h1>
<p>Scenario {html.escape(source)}, seed {scenario.run.seed}. The AR session rendered {s['frames_total']} frames; the tag was
lost in {lost} of them (no object drawn there); {scored}.</p>
{_verdict_section(metrics, scenario, baseline)}
{_links(out)}
{f'<p class="absent">The recording lacks a truth; what needs it is left out:</p><ul class="absent">{truth_note}</ul>' if absent else ''}
<nav><a href="#capture">capture</a><a href="#estimates">light estimates</a><a href="#maps">maps</a><a href="#frames">frames</a>
<a href="#figures">every figure</a><a href="#plots">drift, tracking, frame time</a><a href="#scenario">scenario</a></nav>
{probe}
{_img(out / 'capture' / 'coverage.png', 'coverage', 500)}
{estimates}
<h2 id="maps">Maps</h2><p>Baked from the captured probe (maps/&lt;method&gt;/), each shown by Reinhard's operator.</p>
{_img(out / 'maps' / 'maps.png', 'maps', 1100)}
{maps_table}
<h2 id="frames">AR frames</h2><p>{scored}.</p>{''.join(figures)}
<h2 id="figures">Every figure</h2>
<h3>Capture</h3>{''.join(_absent(why) for why in absent.values())}{_figures_table(metrics, 'capture')}
<h3>AR session</h3>{''.join(_absent(why) for why in absent.values())}{_figures_table(metrics, 'session', ('flip_per_frame',))}
<h2 id="plots">Drift, tracking and frame time</h2>
<h3>IMU drift and its correction</h3>{_absent("the drift against the truth (" + _why(no_poses) + "); shown: how far the capture turned the IMU's orientations") if no_poses else ''}
{_img(out / 'capture' / 'drift.png', 'drift', 900)}
<h3>Tracking</h3>{_absent("the tracking's errors (" + _why(no_poses) + ")") if no_poses else _img(report / 'tracking.png', 'tracking', 900)}
<h3>Frame time</h3>{_img(out / 'profile' / 'timeline.png', 'frame time', 1000)}
<h2 id="scenario">Scenario</h2><details><summary>the scenario as run (absolute paths shortened; scenario.toml has them)</summary>
<pre>{html.escape(_shown_toml(scenario))}</pre></details>
</body></html>
"""
    write_text_atomic(report / "index.html", page)
    return report / "index.html"
