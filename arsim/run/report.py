"""The run's report: one self-contained HTML page (report/index.html, images embedded) with the scenario,
the captured probe beside the truth, the maps per method, the chosen frames, the error tables, and the
drift, tracking and frame-time plots."""

from __future__ import annotations

import base64
import html
import math
from pathlib import Path

import numpy as np

from arsim.core.files import atomic_path, write_text_atomic
from arsim.evaluate.compare_methods import maps_grid
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


def _table(header: list[str], rows: list[list]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


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


def write_report(out: Path, scenario: Scenario, source: str, metrics: dict, tracking: TrackingRun, frames: np.ndarray,
                 maps: dict[str, MapSet]) -> Path:
    """report/index.html. Where the recording lacks a truth (metrics["truth"]), each section that needs it says
    what it leaves out and why instead."""
    report = out / "report"
    report.mkdir(exist_ok=True)
    absent = metrics.get("truth", {})
    no_poses, no_scene = absent.get("groundtruth"), absent.get("scenario")
    exponents = next(iter(maps.values())).exponents
    maps_grid({name: np.stack([m[s] for s in exponents]) for name, m in maps.items()}, exponents, report / "maps.png",
              "Irradiance (s = 1) and reflection maps baked from the captured probe")
    if tracking.measured:
        plot_tracking(tracking, frames, report / "tracking.png")
    c, s = metrics["capture"], metrics["session"]
    capture_rows = [[html.escape(k), html.escape(_num(v)) if not isinstance(v, list) else html.escape("; ".join(map(str, v)) or "none")]
                    for k, v in c.items() if not isinstance(v, dict)]
    map_rows = []
    for name, m in metrics["maps"].items():
        for exp, e in m.get("per_exponent", {}).items():
            map_rows.append([name, "irradiance" if exp == "1" else f"s = {exp}", _num(e["error_vs_truth_same_method_pct"], 2),
                             _num(e["error_vs_truth_accurate_pct"], 2), _num(e["method_error_on_truth_pct"], 2)])
    session_rows = [[k, _num(s.get(k))] for k in ("frames_total", "frames_lost", "frames_tag_visible", "detection_rate_visible",
                                                  "tracking_rot_err_deg_p95", "tracking_trans_err_pct_p95",
                                                  "tracking_trans_err_mm_p95", "flip_mean") if k in s]
    frames = sorted((out / "frames").glob("*.png"))
    flip_of = dict(zip((int(k) for k in s["frames_rendered"]), s.get("flip_per_frame", [])))
    figures = "".join(f"<figure>{_img(f, f.name, 420)}<figcaption>frame {int(f.stem)}"
                      + ("" if no_scene else ": FLIP " + (f"{_num(flip_of.get(int(f.stem)), 4)}" if flip_of.get(int(f.stem)) is not None
                                                         else "n/a (no object drawn)"))
                      + "</figcaption></figure>" for f in frames)
    lost = s.get("frames_lost", 0)
    estimates = _estimates_section(out, metrics.get("estimates", {}), no_scene)
    scored = ("the frames are not scored: " + html.escape(_why(no_scene)) if no_scene else
              f"FLIP against the truth frame: {_num(s.get('flip_mean'), 4)}, the mean over {s.get('flip_frames')} frames "
              f"({'every' if scenario.render.flip_every == 1 else f'every {scenario.render.flip_every}th'} frame with "
              "objects, and the frames shown)")
    if no_scene:
        probe = f"""<h2 id="capture">Captured probe</h2>{_absent("the true environment beside it (" + _why(no_scene) + ")")}
{_img(out / 'capture' / 'probe.png', 'captured probe', 500)}"""
    else:
        probe = f"""<h2 id="capture">Captured probe and the truth</h2>{_img(out / 'capture' / 'probe_vs_truth.png', 'probe vs truth', 1100)}"""
    if no_scene:
        maps_table = _absent("the maps' errors (" + _why(no_scene) + ")")
    else:
        maps_table = f"""<p>Against the same method on the true environment (what the capture costs), against the true environment's accurate
maps (capture and method together), and the method's own error on the true environment. Accurate and bounds maps are
baked on the GL path (float32, held to the NumPy float64 sums within 1e-3 by the tests).</p>
{_table(['method', 'map', 'vs truth, same method', 'vs truth, accurate', 'method on truth'], map_rows)}"""
    truth_note = "".join(f"<li>{html.escape(_why(why))}</li>" for why in absent.values())
    page = f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>arsim run: {html.escape(scenario.run.name)}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:1200px}} table{{border-collapse:collapse;margin:0.5em 0}}
td,th{{border:1px solid #ccc;padding:2px 8px}} td{{text-align:right}} td:first-child{{text-align:left}}
.row{{display:flex;gap:8px;flex-wrap:wrap}} figure{{margin:0}} pre{{background:#f4f4f4;padding:8px;max-height:300px;overflow:auto}}
nav a{{margin-right:1em}} .absent{{color:#8a5a00}}</style></head>
<body><h1>arsim run: {html.escape(scenario.run.name)}</h1>
<p>Scenario {html.escape(source)}, seed {scenario.run.seed}. The AR session rendered {s['frames_total']} frames; the tag was
lost in {lost} of them (no object drawn there); {scored}.</p>
{f'<p class="absent">The recording lacks a truth; what needs it is left out:</p><ul class="absent">{truth_note}</ul>' if absent else ''}
<nav><a href="#scenario">scenario</a><a href="#capture">capture</a><a href="#estimates">light estimates</a><a href="#maps">maps</a><a href="#frames">frames</a>
<a href="#errors">errors</a><a href="#plots">drift, tracking, frame time</a></nav>
<h2 id="scenario">Scenario</h2><pre>{html.escape(scenario_to_toml(scenario))}</pre>
{probe}
{_img(out / 'capture' / 'coverage.png', 'coverage', 500)}
{estimates}
<h2 id="maps">Maps per method</h2><p>Baked from the captured probe (maps/&lt;method&gt;/), each shown by Reinhard's operator.</p>
{_img(report / 'maps.png', 'maps', 1100)}
<h2 id="frames">Frames</h2><div class="row">{figures}</div>
<h2 id="errors">Errors</h2>
<h3>Capture</h3>{''.join(_absent(why) for why in absent.values())}{_table(['metric', 'value'], capture_rows)}
<h3>Maps (mean relative error, %)</h3>
{maps_table}
<h3>AR session</h3>{''.join(_absent(why) for why in absent.values())}{_table(['metric', 'value'], session_rows)}
<h2 id="plots">Drift, tracking and frame time</h2>
<h3>IMU drift and its correction</h3>{_absent("the drift against the truth (" + _why(no_poses) + "); shown: how far the capture turned the IMU's orientations") if no_poses else ''}
{_img(out / 'capture' / 'drift.png', 'drift', 900)}
<h3>Tracking</h3>{_absent("the tracking's errors (" + _why(no_poses) + ")") if no_poses else _img(report / 'tracking.png', 'tracking', 900)}
<h3>Frame time</h3>{_img(out / 'profile' / 'timeline.png', 'frame time', 1000)}
</body></html>
"""
    write_text_atomic(report / "index.html", page)
    return report / "index.html"
