"""The registry of a run's figures: for every figure of metrics.json, its label, unit, meaning, which way is
better and how much change `arsim diff` lets pass; and the report's verdicts, a headline figure per stage judged
against the scenario's [report] thresholds. metrics.json's figures, the report, `arsim diff` and `arsim batch`
all read their names, units and meanings here (README: Reading a run).

A figure is named by its path in metrics.json, its keys joined by dots ("capture.coverage_pct"); "*" in a
registered path stands for one key that varies (a map method, an estimator, an exponent, a step)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from fnmatch import fnmatchcase

LOWER, HIGHER, NEUTRAL = "lower", "higher", ""  # which way is better; neutral: a count or a setting, not judged


@dataclass(frozen=True)
class Metric:
    path: str  # in metrics.json, "*" for one varying key
    label: str
    unit: str  # "" for a ratio or a count
    meaning: str
    better: str = LOWER
    tolerance: float = 0.1  # arsim diff: a change for the worse beyond this fraction of the larger value ...
    floor: float = 0.0  # ... and beyond this absolute change is "worse"
    timed: bool = False  # a measured time or speed: differs from run to run on any machine


# Times are judged loosely (the machines are shared and noisy): worse only beyond 50 % and the floor.
_TIME = dict(tolerance=0.5, timed=True)

METRICS: tuple[Metric, ...] = (
    # capture
    Metric("capture.frames", "frames captured", "frames", "frames of the sweep the capture read", NEUTRAL),
    Metric("capture.frames_per_second", "capture speed", "frames/s", "frames the capture processed per second "
           "of its own time (not the camera's rate)", HIGHER, floor=1.0, **_TIME),
    Metric("capture.coverage_pct", "coverage", "%", "solid angle of the sphere the probe saw", HIGHER, 0.01, 0.5),
    Metric("capture.orientation_rms_deg_corrected", "orientation error, corrected (RMS)", "degrees",
           "camera orientations after drift correction against the truth", floor=0.01),
    Metric("capture.orientation_max_deg_corrected", "orientation error, corrected (max)", "degrees",
           "the worst frame's orientation after drift correction", floor=0.02),
    Metric("capture.orientation_rms_deg_uncorrected", "orientation error, IMU alone (RMS)", "degrees",
           "the fused IMU's orientations, before correction", floor=0.05),
    Metric("capture.orientation_max_deg_uncorrected", "orientation error, IMU alone (max)", "degrees",
           "the fused IMU's worst frame", floor=0.1),
    Metric("capture.orientation_rms_deg_online", "orientation error, online pass (RMS)", "degrees",
           "the online pass's orientations, before the refinement", floor=0.02),
    Metric("capture.alignments_succeeded", "alignments", "frames", "frames the online pass aligned to the probe", NEUTRAL),
    Metric("capture.refined", "refined", "", "1 when the refinement (keyframes and loop closures) ran", NEUTRAL),
    Metric("capture.keyframes", "keyframes", "frames", "keyframes of the refinement", NEUTRAL),
    Metric("capture.loop_closures", "matched pairs", "pairs", "keyframe pairs the refinement used", NEUTRAL),
    Metric("capture.direct_pairs", "directly aligned pairs", "pairs", "of them, those aligned directly", NEUTRAL),
    Metric("capture.seconds_online", "online pass time", "s", "the capture's online pass", floor=1.0, **_TIME),
    Metric("capture.seconds_refinement", "refinement time", "s", "the capture's refinement", floor=1.0, **_TIME),
    Metric("capture.radiance_median_abs_rel_err_pct", "probe radiance error (median)", "%",
           "median relative error of the measured texels against the truth", floor=0.2),
    Metric("capture.radiance_mean_abs_rel_err_pct", "probe radiance error (mean)", "%",
           "mean relative error of the measured texels against the truth", floor=0.2),
    Metric("capture.irradiance_mean_err_pct", "irradiance map error", "%",
           "mean relative error of the irradiance map from the probe against the truth's", floor=0.05),
    Metric("capture.reflection_s80_mean_err_pct", "reflection map error (s = 80)", "%",
           "mean relative error of the s = 80 reflection map against the truth's", floor=0.05),
    Metric("capture.response_median_err_pct", "response error (median)", "%",
           "the calibrated camera response against the true one", floor=0.1),
    Metric("capture.response_max_err_pct", "response error (max)", "%", "the response's worst code", floor=0.5),
    Metric("capture.brightest_source_ratio", "brightest source", "x truth",
           "captured over true luminance of the brightest source (1: all its energy)", NEUTRAL),
    Metric("capture.brightest_source_clipped_pct", "brightest source clipped", "%",
           "its solid angle only ever seen clipped", floor=1.0),
    Metric("capture.rpe_delta_frames", "RPE interval", "frames", "frames between the poses of the RPE", NEUTRAL),
    Metric("capture.ape_rot_*_deg_corrected", "APE rotation, corrected", "degrees",
           "evo's absolute pose error of the rotation, corrected orientations", floor=0.01),
    Metric("capture.rpe_rot_*_deg_corrected", "RPE rotation, corrected", "degrees",
           "evo's relative pose error of the rotation, corrected orientations", floor=0.01),
    Metric("capture.ape_rot_*_deg_uncorrected", "APE rotation, IMU alone", "degrees",
           "evo's absolute pose error of the rotation, the fused IMU", floor=0.05),
    Metric("capture.rpe_rot_*_deg_uncorrected", "RPE rotation, IMU alone", "degrees",
           "evo's relative pose error of the rotation, the fused IMU", floor=0.05),
    Metric("capture.gyro_bias_*", "gyroscope bias estimate", "degrees/s", "the drift filter's residual bias estimate", NEUTRAL),
    # light estimates
    Metric("estimates.*.sh_error", "SH error", "x truth's norm", "the estimate's SH coefficients against the truth's", floor=0.01),
    Metric("estimates.*.main_light_error_deg", "main light direction error", "degrees",
           "angle between the estimated and the true main light", floor=1.0),
    Metric("estimates.*.main_light_intensity_ratio", "main light intensity", "x truth",
           "estimated over true main-light luminance (1 is right)", NEUTRAL),
    Metric("estimates.*.ambient_ratio", "ambient intensity", "x truth", "estimated over true ambient (1 is right)", NEUTRAL),
    Metric("estimates.*.converged_at_frame", "converged at", "frame", "from which the SH error stays within 5 % of its "
           "final value", floor=30),
    Metric("estimates.*.stability", "change a frame", "x truth's norm", "the SH's mean change from frame to frame",
           floor=0.001),
    Metric("estimates.*.diffuse_sphere_rmse", "diffuse sphere RMSE", "x truth's mean",
           "a diffuse sphere lit by the estimate against the truth", floor=0.005),
    Metric("estimates.*.mirror_sphere_hdr_flip", "mirror sphere HDR-FLIP", "FLIP (0-1)",
           "a mirror sphere lit by the estimate against the truth", floor=0.01),
    Metric("estimates.*.ar_flip_mean", "AR objects' FLIP, lit by the estimate", "FLIP (0-1)",
           "the objects lit by the estimate against the truth frame, over their mask", floor=0.005),
    # maps
    Metric("maps.*.seconds", "bake time", "s", "the method's bake of every map", floor=0.5, **_TIME),
    Metric("maps.*.per_exponent.*.error_vs_truth_same_method_pct", "map error vs the truth's, same method", "%",
           "what the capture costs: the map against the same method's on the true environment", floor=0.05),
    Metric("maps.*.per_exponent.*.error_vs_truth_accurate_pct", "map error vs the truth's accurate map", "%",
           "capture and method together: against the exact map of the true environment", floor=0.05),
    Metric("maps.*.per_exponent.*.method_error_on_truth_pct", "method's own error", "%",
           "the method on the true environment against the exact map", floor=0.05),
    # session
    Metric("session.tracking_rot_err_deg_p95", "tracking rotation error (p95)", "degrees",
           "the tag's pose against the truth, frames with the tag in view", floor=0.02),
    Metric("session.tracking_trans_err_pct_p95", "tracking position error (p95)", "% of distance",
           "the tag's position against the truth", floor=0.05),
    Metric("session.tracking_trans_err_mm_p95", "tracking position error (p95)", "mm", "the tag's position against the truth",
           floor=0.5),
    Metric("session.extrapolated_rot_err_deg_p95", "extrapolated rotation error (p95)", "degrees",
           "poses carried by the IMU while the tag was lost", floor=0.05),
    Metric("session.extrapolated_trans_err_pct_p95", "extrapolated position error (p95)", "% of distance",
           "positions carried by the IMU while the tag was lost", floor=0.1),
    Metric("session.extrapolated_s_max", "longest extrapolation", "s", "the IMU carried the pose this long at most", NEUTRAL),
    Metric("session.frames_total", "AR frames", "frames", "frames the AR session rendered", NEUTRAL),
    Metric("session.frames_lost", "frames lost", "frames", "frames without a pose (no object drawn)", floor=3),
    Metric("session.frames_tag_visible", "tag in view", "frames", "frames with the whole tag in view", NEUTRAL),
    Metric("session.frames_extrapolated", "frames extrapolated", "frames", "frames posed by the IMU alone", NEUTRAL),
    Metric("session.detection_rate_visible", "detection rate", "", "share of frames with the tag in view where it was "
           "found", HIGHER, 0.01, 0.005),
    Metric("session.found_while_not_visible", "found while not fully in view", "frames",
           "frames where the tag was found though partly out of view", NEUTRAL),
    Metric("session.flip_mean", "AR frames' FLIP", "FLIP (0-1)", "the objects against the truth frame drawn at the "
           "tracked pose, over the objects' mask: the light, not the tracking", floor=0.002),
    Metric("session.flip_frames", "frames scored", "frames", "frames with objects scored by FLIP", NEUTRAL),
    Metric("session.lit_by_truth", "lit by the truth's own maps", "", "1: the objects were lit by the true "
           "environment's maps, so the FLIP is 0 by construction", NEUTRAL),
    Metric("session.within_budget_pct", "frames within budget", "%", "frames whose steps 3-7 took at most the "
           "frame budget", HIGHER, 0.02, 1.0, timed=True),
    Metric("session.budget_ms", "frame budget", "ms", "the profile's frame budget", NEUTRAL),
    Metric("session.step_ms.*", "step time (CPU, median)", "ms", "a render-loop step's median CPU time",
           floor=0.5, **_TIME),
    Metric("session.step_gl_ms.*", "step time (GL, median)", "ms", "a render-loop step's median GPU time (valid "
           "timer readings only)", floor=0.5, **_TIME),
    Metric("session.step_gl_dropped.*.*", "GL timer readings dropped", "readings", "a step's GL timer readings that "
           "were no time (zero, clamped at 2^32 - 1 ns, negative, unavailable), by why", NEUTRAL),
)


def metric_for(path: str) -> Metric | None:
    """The registered figure a path of metrics.json is (the first pattern that matches), or None."""
    parts = path.split(".")
    for m in METRICS:
        pattern = m.path.split(".")
        if len(pattern) == len(parts) and all(fnmatchcase(p, q) for p, q in zip(parts, pattern)):
            return m
    return None


def label_of(path: str) -> str:
    """The figure's label with what its pattern's "*" stood for (a method, an estimator, an exponent, a step):
    "map error vs the truth's accurate map (fast, s = 80)"; the path itself where it is not registered."""
    m = metric_for(path)
    if m is None:
        return path
    varying = []
    for part, pattern in zip(path.split("."), m.path.split(".")):
        if pattern == "*":
            varying.append(part)
        elif "*" in pattern:  # e.g. ape_rot_*_deg_corrected: the statistic
            head, tail = pattern.split("*", 1)
            varying.append(part[len(head):len(part) - len(tail)])
    if m.path.startswith("maps.") and len(varying) == 2:
        varying[1] = "irradiance" if varying[1] == "1" else f"s = {varying[1]}"
    return m.label + (f" ({', '.join(varying)})" if varying else "")


def figures_of(metrics: dict) -> dict[str, float]:
    """Every number of metrics.json by its path (booleans as 0/1; the "truth" notes, per-frame series, lists and
    strings left out), in the file's order."""
    out: dict[str, float] = {}

    def walk(value, path: str) -> None:
        if isinstance(value, bool):
            out[path] = float(value)
        elif isinstance(value, (int, float)):
            out[path] = float(value)
        elif isinstance(value, dict):
            for k, v in value.items():
                if k != "truth" and not str(k).endswith("_per_frame"):  # (per-frame series are not figures)
                    walk(v, f"{path}.{k}" if path else str(k))

    walk(metrics, "")
    return out


def unit_text(metric: Metric | None, value: float) -> str:
    """A figure with its unit, as the report and diff print it."""
    if value is None or not math.isfinite(value):
        return "n/a"
    digits = 0 if metric is not None and metric.unit in ("frames", "frame", "pairs", "readings") else 4 if abs(value) < 0.1 else 3
    text = f"{value:.{digits}f}" if value != int(value) or digits else f"{int(value)}"
    return f"{text} {metric.unit}".rstrip() if metric is not None and metric.unit else text


def worse_beyond_tolerance(metric: Metric | None, a: float, b: float) -> bool:
    """Whether b is worse than a by more than the metric's tolerance (relative to the larger) and its floor."""
    if metric is None or metric.better == NEUTRAL or not (math.isfinite(a) and math.isfinite(b)):
        return False
    change = b - a if metric.better == LOWER else a - b
    return change > max(metric.tolerance * max(abs(a), abs(b)), metric.floor)


# ----------------------------------------------------------------------------------------------------------
# Verdicts: a headline figure per stage against the scenario's [report] thresholds (warn, fail).

@dataclass(frozen=True)
class Verdict:
    stage: str
    metric: Metric
    value: float | None  # None: not measured (and why in note)
    warn: float
    fail: float
    note: str = ""
    path: str = ""  # the figure judged (the worst where several are)
    by_construction: bool = False  # what it is by construction (0 FLIP with the truth's own maps): not judged

    @property
    def status(self) -> str:
        """pass, warn, fail; or n/a where the figure was not measured or is what it is by construction."""
        if self.value is None or not math.isfinite(self.value) or self.by_construction:
            return "n/a"
        worse = (lambda x, t: x > t) if self.metric.better != HIGHER else (lambda x, t: x < t)
        return "fail" if worse(self.value, self.fail) else "warn" if worse(self.value, self.warn) else "pass"

    def threshold_text(self) -> str:
        sign = "≤" if self.metric.better != HIGHER else "≥"
        return (f"pass {sign} {unit_text(self.metric, self.warn)}, "
                f"fail {'>' if sign == '≤' else '<'} {unit_text(self.metric, self.fail)}")


# Each verdict: stage, the figure's path (a "{method}" filled with [render] method), the [report] key of its
# thresholds, and how to take it from the figures where it is a worst case over several.
VERDICTS = (
    ("capture", "capture.orientation_rms_deg_corrected", "capture_orientation_deg"),
    ("capture", "capture.irradiance_mean_err_pct", "capture_irradiance_pct"),
    ("maps", "maps.{method}.per_exponent.*.error_vs_truth_accurate_pct", "maps_error_pct"),
    ("tracking", "session.tracking_rot_err_deg_p95", "tracking_rotation_deg"),
    ("tracking", "session.tracking_trans_err_pct_p95", "tracking_position_pct"),
    ("AR frames", "session.flip_mean", "ar_flip"),
    ("frame budget", "session.within_budget_pct", "within_budget_pct"),
)


def verdicts(metrics: dict, method: str, thresholds) -> list[Verdict]:
    """The run's verdicts. thresholds: the scenario's [report] section ((warn, fail) per VERDICTS key). A figure
    over several values (the maps' exponents) is judged by its worst. The AR frames' FLIP is n/a where the objects
    were lit by the truth's own maps (zero by construction)."""
    figures = figures_of(metrics)
    out = []
    for stage, path, key in VERDICTS:
        pattern = path.format(method=method)
        metric = metric_for(pattern.replace("*", "1"))
        values = {p: v for p, v in figures.items() if fnmatchcase(p, pattern)}
        warn, fail = getattr(thresholds, key)
        note, worst = "", pattern
        if not values:
            absent = metrics.get("truth", {})
            note = "not measured" + (f": {next(iter(absent.values()))}" if absent else "")
            value = None
        else:
            worst = (max if metric.better != HIGHER else min)(values, key=values.get)
            value = values[worst]
            if len(values) > 1:
                note = f"worst of {len(values)}"
        by_construction = path == "session.flip_mean" and bool(metrics.get("session", {}).get("lit_by_truth"))
        if by_construction:
            note = "by construction 0: the objects were lit by the true environment's own maps"
        out.append(Verdict(stage, metric, value, warn, fail, note, worst, by_construction))
    return out
