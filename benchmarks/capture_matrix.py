"""The capture's fidelity over a matrix of cases: every bundled environment with three seeds, each at a quarter
of its intensity (the dim case), the drifting gyroscope's device on three environments, a 20 s sweep, the
night scene. Each case is recorded (the sweep only) and captured, then merged twice more from the same frames:
at the capture's orientations with the true response (what the response costs) and at the true orientations
with the true response (the ideal merge, the floor the camera's noise leaves). One row per case, then the
medians and the worst cases; the table as Markdown and JSON, and matrix.png.

    python benchmarks/capture_matrix.py -o matrix            # every case (37): about 60-70 minutes on 2 cores
    python benchmarks/capture_matrix.py -o matrix --quick    # 4 cases: about 7 minutes
    python benchmarks/capture_matrix.py -o matrix --only night,dim-city
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from arsim.capture.pipeline import CaptureSettings, accumulate_frames, capture, recording_scenario
from arsim.capture.response import RecoveredResponse, response_error
from arsim.core.assets import assets_dir, scenarios_dir
from arsim.core.errors import ArsimError
from arsim.core.files import json_text, write_text_atomic
from arsim.core.progress import progress_bar
from arsim.evaluate.capture_report import capture_metrics, probe_map_errors
from arsim.scenario.environment import load_environment
from arsim.scenario.loader import parse_scenario
from arsim.sensors.camera import ResponseCurve
from arsim.sensors.recording import load_recording, record

ENVIRONMENTS = sorted(p.stem for p in (assets_dir() / "envmaps").glob("*.exr"))
DRIFTING = (scenarios_dir() / "drifting_gyro.toml").read_text(encoding="utf-8")
GYRO = DRIFTING[DRIFTING.index("[device.gyroscope]"):]  # the drifting device's gyroscope section

# (column, key in the capture's metrics, digits)
COLUMNS = (("orientation RMS corrected (deg)", "orientation_rms_deg_corrected", 3),
           ("uncorrected (deg)", "orientation_rms_deg_uncorrected", 2),
           ("online pass (deg)", "orientation_rms_deg_online", 3),
           ("coverage %", "coverage_pct", 1),
           ("irradiance err %", "irradiance_mean_err_pct", 2),
           ("s=80 err %", "reflection_s80_mean_err_pct", 2),
           ("brightest source ratio", "brightest_source_ratio", 3),
           ("true response irradiance err %", "true_response_irradiance_err_pct", 2),
           ("ideal merge irradiance err %", "ideal_irradiance_err_pct", 2),
           ("ideal merge s=80 err %", "ideal_s80_err_pct", 2),
           ("frames/s", "frames_per_second", 1))


def case_toml(env: str, seed: int, intensity: float = 1.0, extra: str = "") -> str:
    return (f'[run]\nname = "matrix"\nseed = {seed}\n[environment]\nmap = "envmaps/{env}.exr"\nprobe_size = 512\n'
            f"intensity = {intensity}\n[ar]\nenabled = false\n{extra}")


def cases() -> dict[str, str]:
    """Every case of the matrix by name: its scenario's TOML. In the order they run: every kind of case
    before the second and third seeds (a run cut short still covers every kind)."""
    out = {f"{env}-s0": case_toml(env, 0) for env in ENVIRONMENTS}
    for env in ENVIRONMENTS:
        out[f"dim-{env}"] = case_toml(env, 0, 0.25)
    for env in ("courtyard", "interior", "city"):
        out[f"drifting-{env}"] = case_toml(env, 4, extra="[capture]\nduration_s = 20.0\n" + GYRO)
    out["sweep-20s"] = case_toml("interior", 0, extra="[capture]\nduration_s = 20.0\n")
    night = (scenarios_dir() / "night.toml").read_text(encoding="utf-8")
    out["night"] = night + "\n[ar]\nenabled = false\n" if "[ar]" not in night else night.replace("[ar]", "[ar]\nenabled = false", 1)
    for seed in (1, 2):
        out.update({f"{env}-s{seed}": case_toml(env, seed) for env in ENVIRONMENTS})
    return out


QUICK = ("interior-s0", "dim-sunrise", "drifting-courtyard", "sweep-20s")


def run_case(text: str, work: Path) -> dict:
    """Record the sweep and capture it: the capture's metrics, or the one line that stopped it."""
    scenario = parse_scenario(text, "matrix case", assets_dir())
    start = time.perf_counter()
    try:
        record(scenario, work / "rec")
        rec = load_recording(work / "rec")
        sc = recording_scenario(rec)
        settings = CaptureSettings.of(sc)
        result = capture(rec, settings)
    except ArsimError as exc:
        return {"status": f"refused: {exc}", "seconds": time.perf_counter() - start}
    cam = sc.device.camera
    true_response = ResponseCurve(cam.response, cam.gamma, cam.contrast).decode(np.arange(256))
    truth = load_environment(dataclasses.replace(sc.environment, probe_size=settings.size))
    metrics, _ = capture_metrics(result, truth, response_error(result.response, true_response))
    # The causes: the same frames merged at the capture's orientations with the true response, and the
    # floor: at the true orientations with the true response (the ideal merge)
    exact = RecoveredResponse(np.repeat(true_response[:, None], 3, axis=1))
    responded, _ = probe_map_errors(accumulate_frames(rec, result.corrected, exact, settings.size), truth)
    metrics["true_response_irradiance_err_pct"] = responded[0].mean_percent
    floor, _ = probe_map_errors(accumulate_frames(rec, result.truth, exact, settings.size), truth)
    metrics["ideal_irradiance_err_pct"], metrics["ideal_s80_err_pct"] = floor[0].mean_percent, floor[1].mean_percent
    return {"status": "ok", "seconds": time.perf_counter() - start, **{k: metrics[k] for _, k, _ in COLUMNS}}


def table(rows: dict[str, dict]) -> str:
    header = "| case | status | " + " | ".join(c for c, _, _ in COLUMNS) + " |"
    lines = [header, "|" + "---|" * (len(COLUMNS) + 2)]
    for name, r in rows.items():
        cells = [f"{r[k]:.{d}f}" if k in r else "" for _, k, d in COLUMNS]
        lines.append(f"| {name} | {r['status'] if r['status'] == 'ok' else r['status'][:80]} | " + " | ".join(cells) + " |")
    done = [r for r in rows.values() if r["status"] == "ok"]
    if done:
        for label, f in (("median", np.median), ("worst", None)):
            cells = []
            for _, k, d in COLUMNS:
                values = np.array([r[k] for r in done])
                if f is not None:
                    value = f(values)
                elif k in ("coverage_pct", "frames_per_second"):
                    value = values.min()
                elif k == "brightest_source_ratio":
                    value = values[np.argmax(np.abs(np.log(values)))]
                else:
                    value = values.max()
                cells.append(f"{value:.{d}f}")
            lines.append(f"| **{label}** | {len(done)} of {len(rows)} ok | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(rows: dict[str, dict], path: Path) -> None:
    """matrix.png: per case, the orientation error (refined, online pass, IMU alone) and the irradiance and
    s = 80 errors against the ideal merge's (log scales: the cases span three decades)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = {name: r for name, r in rows.items() if r["status"] == "ok"}
    if not done:
        return
    names, x = list(done), np.arange(len(done))
    fig, axes = plt.subplots(2, 1, figsize=(max(8.0, 0.32 * len(names)), 7.5), sharex=True)
    for offset, key, label in ((-0.27, "orientation_rms_deg_corrected", "refined"),
                               (0.0, "orientation_rms_deg_online", "online pass"),
                               (0.27, "orientation_rms_deg_uncorrected", "IMU alone")):
        axes[0].bar(x + offset, [done[n][key] for n in names], 0.27, label=label)
    axes[0].axhline(0.3, color="k", lw=0.8, ls="--", label="0.3°")
    axes[0].set(yscale="log", ylabel="orientation RMS (degrees)")
    for offset, key, label in ((-0.3, "irradiance_mean_err_pct", "irradiance"),
                               (-0.1, "ideal_irradiance_err_pct", "irradiance, ideal merge"),
                               (0.1, "reflection_s80_mean_err_pct", "s = 80"),
                               (0.3, "ideal_s80_err_pct", "s = 80, ideal merge")):
        axes[1].bar(x + offset, [max(done[n][key], 1e-3) for n in names], 0.2, label=label)
    axes[1].set(yscale="log", ylabel="map mean error (%)")
    axes[1].set_xticks(x, names, rotation=70, ha="right", fontsize=8)
    for ax in axes:
        ax.legend(fontsize=8, ncol=4)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle(f"Capture fidelity matrix: {len(done)} of {len(rows)} cases captured")
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="example:\n  python benchmarks/capture_matrix.py -o matrix --quick")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="DIR",
                        help="writes matrix.md, matrix.json and matrix.png")
    parser.add_argument("--plot-only", action="store_true", help="redraw matrix.png from DIR/matrix.json")
    parser.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)}")
    parser.add_argument("--only", metavar="NAMES", help="comma-separated case names")
    args = parser.parse_args()
    if args.plot_only:
        plot(json.loads((args.output / "matrix.json").read_text(encoding="utf-8")), args.output / "matrix.png")
        return 0
    every = cases()
    names = list(QUICK) if args.quick else (args.only.split(",") if args.only else list(every))
    unknown = [n for n in names if n not in every]
    if unknown:
        print(f"capture_matrix: unknown case {unknown[0]}; the cases: {', '.join(every)}", file=sys.stderr)
        return 2
    args.output.mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict] = {}
    with progress_bar(f"capture matrix: {len(names)} cases", len(names)) as update:
        for k, name in enumerate(names):
            work = Path(tempfile.mkdtemp(prefix="capture-matrix-"))
            try:
                rows[name] = run_case(every[name], work)
            finally:
                shutil.rmtree(work, ignore_errors=True)
            r = rows[name]
            print(f"{name}: {r['status']}" + (f", {r['orientation_rms_deg_corrected']:.3f} deg, irradiance "
                                              f"{r['irradiance_mean_err_pct']:.2f} %, s=80 {r['reflection_s80_mean_err_pct']:.2f} %"
                                              if r["status"] == "ok" else "") + f" ({r['seconds']:.0f} s)", flush=True)
            update(completed=k + 1)
            # written after every case: a run stopped early keeps what it measured
            write_text_atomic(args.output / "matrix.md", f"# Capture fidelity matrix\n\n{len(rows)} of {len(names)} "
                              "cases\n\n" + table(rows))
            write_text_atomic(args.output / "matrix.json", json_text(rows))
    plot(rows, args.output / "matrix.png")
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
