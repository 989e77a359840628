"""What a capture run is measured by, against the truth: metrics.json, the captured and true probes as
EXR, the coverage, drift and probe-versus-truth plots, and the orientations as TUM trajectory files. Where
the recording lacks a truth (no groundtruth.csv, no scenario), what needs it is left out and metrics.json's
"truth" says why."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from arsim.capture.accumulate import filled
from arsim.capture.pipeline import CaptureResult
from arsim.core.conventions import anglemap_disk_mask, anglemap_solid_angles
from arsim.core.files import json_text, write_text_atomic
from arsim.core.hdr_io import write_image
from arsim.evaluate.metrics import map_error
from arsim.evaluate.recording_plots import _pyplot, _save
from arsim.evaluate.trajectories import TRAJECTORY_FILES, rotation_ape_rpe, rpe_delta_frames, write_tum
from arsim.lighting.fast import fast_maps
from arsim.sensors.camera import LUMA

MAP_EXPONENTS = (1.0, 80.0)  # the irradiance map and a glossy reflection map
BRIGHTEST_FRACTION = 0.1  # the brightest source: texels above this fraction of the truth's peak luminance
BRIGHTEST_MARGIN = 3  # and those within this many texels (about 2 degrees at 512²): a residual shift of a
# sun one texel wide is the alignment's error, counted there, not lost energy

def orientation_errors_deg(a: Rotation, b: Rotation) -> np.ndarray:
    return np.degrees((a.inv() * b).magnitude())


def probe_map_errors(acc, truth: np.ndarray) -> tuple[list, np.ndarray]:
    """The errors of the irradiance and reflection maps (MAP_EXPONENTS) of an accumulator's probe (holes
    filled) against the truth's, and the filled probe."""
    inside = anglemap_disk_mask(acc.size)
    complete = filled(acc.probe(), acc.covered() & inside)
    maps_probe, maps_truth = fast_maps(complete, MAP_EXPONENTS), fast_maps(truth, MAP_EXPONENTS)
    return [map_error(maps_truth[k][inside], maps_probe[k][inside]) for k in range(len(MAP_EXPONENTS))], complete


def capture_metrics(result: CaptureResult, truth: np.ndarray | None, true_response_error: dict | None,
                    fps: float = 30.0, absent: dict | None = None) -> tuple[dict, np.ndarray]:
    """metrics.json's content and the probe with its holes filled. What needs a truth the recording lacks is
    left out: the orientation errors without result.truth (no groundtruth.csv), the probe's, maps' and
    brightest source's without the true environment `truth`, the response's without its true error; `absent`
    (sensors.frames.truth_absent) is written as "truth", saying why. fps: the camera's, for the RPE's step."""
    acc = result.accumulator
    n = acc.size
    inside = anglemap_disk_mask(n)
    metrics = {"frames": len(result.t_s), "frames_per_second": result.frames_per_second, "coverage_pct": 100 * acc.coverage()}
    if result.truth is not None:
        corrected = orientation_errors_deg(result.corrected, result.truth)
        uncorrected = orientation_errors_deg(result.uncorrected, result.truth)
        online = orientation_errors_deg(result.online, result.truth)
        metrics |= {
            "orientation_rms_deg_corrected": float(np.sqrt(np.mean(corrected**2))),
            "orientation_max_deg_corrected": float(corrected.max()),
            "orientation_rms_deg_uncorrected": float(np.sqrt(np.mean(uncorrected**2))),
            "orientation_max_deg_uncorrected": float(uncorrected.max()),
            "orientation_rms_deg_online": float(np.sqrt(np.mean(online**2))),
        }
    metrics |= {
        "alignments_succeeded": int(result.aligned.sum()),
        "refined": result.refinement is not None,
        "keyframes": 0 if result.refinement is None else len(result.refinement.keyframes),
        "loop_closures": 0 if result.refinement is None else result.refinement.loop_closures,
        "direct_pairs": 0 if result.refinement is None else result.refinement.direct_pairs,
        "gyro_bias_dps_online": np.degrees(result.gyro_bias[0]).tolist(),
        "gyro_bias_sigma_dps_online": np.degrees(result.gyro_bias[1]).tolist(),
        "seconds_online": result.seconds_online,
        "seconds_refinement": result.seconds - result.seconds_online,
    }
    if truth is None:
        complete = filled(acc.probe(), acc.covered() & inside)
    else:
        metrics_env, complete = _environment_metrics(acc, truth)
        metrics |= {k: metrics_env[k] for k in ("radiance_median_abs_rel_err_pct", "radiance_mean_abs_rel_err_pct",
                                                "irradiance_mean_err_pct", "reflection_s80_mean_err_pct")}
    if true_response_error is not None:
        metrics |= {"response_median_err_pct": true_response_error["median_pct"],
                    "response_max_err_pct": true_response_error["max_pct"]}
    if truth is not None:
        metrics |= {k: metrics_env[k] for k in ("brightest_source_ratio", "brightest_source_clipped_pct")}
    if result.truth is not None:
        # The same errors as the SLAM community reports them (evo): APE and RPE of the rotation, degrees.
        delta = rpe_delta_frames(fps, len(result.t_s))
        for name, estimate in (("corrected", result.corrected), ("uncorrected", result.uncorrected)):
            metrics |= {f"{k}_{name}": v for k, v in rotation_ape_rpe(result.t_s, result.truth, estimate, delta).items()}
        metrics["rpe_delta_frames"] = delta
    if absent:
        metrics["truth"] = dict(absent)
    return metrics, complete


def _environment_metrics(acc, truth: np.ndarray) -> tuple[dict, np.ndarray]:
    """The probe against the true environment: its radiance where measured, its maps, the brightest source."""
    n = acc.size
    inside = anglemap_disk_mask(n)
    probe, covered = acc.probe(), acc.covered() & inside
    measured = covered & ~acc.clipped_only()
    eps = 1e-4 * truth[inside].mean()
    rel = np.abs(probe[measured] - truth[measured]) / (truth[measured] + eps)
    map_err, complete = probe_map_errors(acc, truth)
    omega = anglemap_solid_angles(n)
    luminance_truth, luminance_probe = truth @ LUMA, complete @ LUMA
    core = (luminance_truth >= BRIGHTEST_FRACTION * luminance_truth[inside].max()).astype(np.uint8)
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * BRIGHTEST_MARGIN + 1, 2 * BRIGHTEST_MARGIN + 1))
    brightest = inside & (cv2.dilate(core, disk) > 0)
    ratio = float((luminance_probe[brightest] * omega[brightest]).sum() / (luminance_truth[brightest] * omega[brightest]).sum())
    clipped = float((omega[brightest & acc.clipped_only()]).sum() / omega[brightest].sum())
    return {
        "radiance_median_abs_rel_err_pct": float(100 * np.median(rel)),
        "radiance_mean_abs_rel_err_pct": float(100 * rel.mean()),
        "irradiance_mean_err_pct": map_err[0].mean_percent,
        "reflection_s80_mean_err_pct": map_err[1].mean_percent,
        "brightest_source_ratio": ratio,
        "brightest_source_clipped_pct": 100 * clipped,
    }, complete


def unmatched_warning(metrics: dict) -> str | None:
    """Where nothing could be matched (no texture anywhere), the orientations are the gyroscope's alone."""
    if metrics["alignments_succeeded"] or metrics["loop_closures"]:
        return None
    sigma = max(metrics["gyro_bias_sigma_dps_online"])
    return ("no frame could be aligned and no keyframes matched (a scene without features): the orientations are "
            "the IMU's alone, with the fusion's bias estimate (nothing measured it: its prior, 0 ± "
            f"{sigma:.2g} degrees/s per axis from the device's figures, gyro_bias_dps_online); drift.png shows how far "
            "that is off")


def brightest_warning(metrics: dict) -> str | None:
    if "brightest_source_ratio" not in metrics:  # (no true environment to compare with)
        return None
    ratio, clipped = metrics["brightest_source_ratio"], metrics["brightest_source_clipped_pct"]
    if 0.8 <= ratio <= 1.25:
        return None
    if clipped > 1.0:
        return (f"the brightest source was clipped in every frame that saw {clipped:.0f} % of it, even at the shortest "
                f"exposure: its captured radiance is a lower bound, {100 * ratio:.1f} % of the truth (the exposure range "
                "cannot hold it); see probe_vs_truth.png and coverage.png")
    return (f"the brightest source's captured radiance is {100 * ratio:.1f} % of the truth: it was seen unclipped, but the "
            "frames disagree where it is (alignment error where it was seen); see probe_vs_truth.png and drift.png")


def plot_drift(result: CaptureResult, path: Path) -> Path:
    """drift.png: the capture's orientations against the truth; without a ground truth, how far the capture
    turned the IMU's orientations (the drift it corrected, as far as the alignment saw it)."""
    online = [("online alignment", result.online, 0.7)] if result.refinement is not None else []
    if result.truth is not None:
        reference, ylabel, title = (result.truth, "camera orientation error (degrees)",
                                    "Drift of the capture's orientation against the truth")
        last = "refined (what the probe holds)" if online else "with feature alignment"
        curves = [("IMU only (uncorrected)", result.uncorrected, 1.0), *online, (last, result.corrected, 1.0)]
    else:
        reference, ylabel, title = (result.uncorrected, "angle from the IMU's orientation (degrees)",
                                    "The capture's correction of the IMU's orientation (the recording has no ground truth)")
        curves = [*online, ("what the probe holds", result.corrected, 1.0)]
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.5))
    for label, orientations, alpha in curves:
        ax.plot(result.t_s, orientation_errors_deg(orientations, reference), label=label, alpha=alpha)
    # a rug along the bottom (axes coordinates), off the curves that start at zero
    ax.plot(result.t_s[result.aligned], np.full(int(result.aligned.sum()), 0.02), "|", ms=4, color="tab:gray",
            transform=ax.get_xaxis_transform(), label="online alignment succeeded (frames)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)  # beside the axes: off the curves
    return _save(fig, path)


ANGLE_MAP_AXES = "angle map: centre +z, up +y, right +x, rim -z"


def _radiance_colorbar(fig, ax, scale: float, what: str) -> None:
    """A grey ramp for images shown as clip(x * scale, 0, 1)^(1/2.2): the radiance each shade stands for."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import PowerNorm

    fig.colorbar(ScalarMappable(PowerNorm(1 / 2.2, vmin=0.0, vmax=1.0 / scale), cmap="gray"), ax=ax, shrink=0.8,
                 extend="max", label=f"{what} radiance per channel\n(the environment's units, gamma 2.2)")


def coverage_map_figure(result: CaptureResult):
    plt = _pyplot()
    acc = result.accumulator
    weight = acc.weights.sum(axis=0).mean(axis=-1)
    fig, ax = plt.subplots(figsize=(5.5, 5))
    seen = weight > 0
    relative = np.where(seen, weight / (weight[seen].max() if seen.any() else 1.0), np.nan)
    shown = np.where(anglemap_disk_mask(acc.size) & seen, np.log10(np.maximum(relative, 1e-6)), np.nan)
    image = ax.imshow(shown, cmap="magma", vmin=-6, vmax=0)
    ax.contour(acc.clipped_only(), levels=[0.5], colors="cyan", linewidths=0.7)
    fig.colorbar(image, ax=ax, shrink=0.85, extend="min",
                 label="log10 of the texel's summed weight\n(relative to the largest; unitless)")
    ax.set_title(f"Captured weight per texel; {100 * acc.coverage():.2f} % covered\n(cyan: only ever seen clipped)")
    ax.set_xlabel(ANGLE_MAP_AXES, fontsize=8)
    ax.set_xticks([])
    ax.set_yticks([])
    return fig


def plot_coverage_map(result: CaptureResult, path: Path) -> Path:
    return _save(coverage_map_figure(result), path)


def plot_probe(probe: np.ndarray, path: Path) -> Path:
    """The captured probe alone (where the true environment is unknown), exposed for its median luminance."""
    plt = _pyplot()
    inside = anglemap_disk_mask(probe.shape[0])
    scale = 0.18 / max(float(np.median((probe @ LUMA)[inside])), 1e-12)
    fig, ax = plt.subplots(figsize=(6.5, 5))
    ax.imshow(np.clip(np.maximum(probe * scale, 0.0) ** (1 / 2.2), 0, 1))
    ax.set_title("captured (holes filled); no true environment to compare with")
    _radiance_colorbar(fig, ax, scale, "captured")
    ax.set_xlabel(ANGLE_MAP_AXES, fontsize=8)
    ax.set_xticks([])
    ax.set_yticks([])
    return _save(fig, path)


def probe_vs_truth_figure(probe: np.ndarray, truth: np.ndarray):
    """The captured probe and the truth on one exposure (a grey ramp gives the radiance of each shade), and
    the relative error of luminance per texel (its colour bar in percent, clipped at 20 %)."""
    plt = _pyplot()
    inside = anglemap_disk_mask(probe.shape[0])
    scale = 0.18 / max(float(np.median((truth @ LUMA)[inside])), 1e-12)  # the same exposure for both

    def shown(x):
        return np.clip(np.maximum(x * scale, 0.0) ** (1 / 2.2), 0, 1)  # (a probe may hold slightly negative texels)

    rel = np.where(inside, np.abs(probe @ LUMA - truth @ LUMA) / (truth @ LUMA + 1e-4 * (truth @ LUMA)[inside].mean()), np.nan)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8))
    axes[0].imshow(shown(probe))
    axes[0].set_title("captured (holes filled)")
    axes[1].imshow(shown(truth))
    axes[1].set_title("truth")
    _radiance_colorbar(fig, axes[:2].tolist(), scale, "captured and true")
    image = axes[2].imshow(100 * rel, cmap="viridis", vmin=0, vmax=20)
    axes[2].set_title("relative error of luminance")
    fig.colorbar(image, ax=axes[2], shrink=0.8, extend="max", label="|captured - true| / true luminance (%)")
    for ax in axes:
        ax.set_xlabel(ANGLE_MAP_AXES, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    return fig


def plot_probe_vs_truth(probe: np.ndarray, truth: np.ndarray, path: Path) -> Path:
    return _save(probe_vs_truth_figure(probe, truth), path)


def write_capture(result: CaptureResult, truth: np.ndarray | None, response_error: dict | None, out_dir: Path,
                  fps: float = 30.0, absent: dict | None = None) -> dict:
    """Everything `arsim capture` writes into out_dir; returns the metrics. truth: the true environment (None
    where unknown: truth.exr is not written, probe.png shows the probe alone instead of probe_vs_truth.png);
    the orientations as TUM trajectory files (trajectory_truth.tum only where the recording has a truth)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    metrics, complete = capture_metrics(result, truth, response_error, fps, absent)
    write_image(out_dir / "env.exr", result.accumulator.probe())
    plot_coverage_map(result, out_dir / "coverage.png")
    plot_drift(result, out_dir / "drift.png")
    if truth is not None:
        write_image(out_dir / "truth.exr", truth)
        plot_probe_vs_truth(complete, truth, out_dir / "probe_vs_truth.png")
    else:
        plot_probe(complete, out_dir / "probe.png")
    streams = {"capture": result.corrected, "fused": result.uncorrected, "truth": result.truth}
    for name, rotations in streams.items():
        if rotations is not None:
            write_tum(out_dir / TRAJECTORY_FILES[name], result.t_s, rotations)
    warnings = [w for w in (brightest_warning(metrics), unmatched_warning(metrics)) if w]
    write_text_atomic(out_dir / "metrics.json", json_text(metrics | {"warnings": warnings}))
    return metrics | {"warnings": warnings}
