"""The registry of a run's figures and the report's verdicts (evaluate.registry)."""

import math

from arsim.evaluate.registry import (HIGHER, label_of, metric_for, unit_text, verdicts, worse_beyond_tolerance)
from arsim.scenario.sections import ReportSection


def metrics(rms=0.1, irradiance=0.5, map_errors=(0.3, 1.2), rot=0.1, pos=0.2, flip=0.01, within=99.0, **session):
    return {"capture": {"orientation_rms_deg_corrected": rms, "irradiance_mean_err_pct": irradiance},
            "maps": {"fast": {"seconds": 0.1, "per_exponent": {str(s): {"error_vs_truth_accurate_pct": e}
                                                               for s, e in zip((1, 80), map_errors)}}},
            "session": {"tracking_rot_err_deg_p95": rot, "tracking_trans_err_pct_p95": pos, "flip_mean": flip,
                        "within_budget_pct": within, **session}}


def by_stage(vs):
    return {(v.stage, v.metric.path): v for v in vs}


def test_verdicts_pass_warn_and_fail_against_the_thresholds():
    t = ReportSection()
    vs = verdicts(metrics(), "fast", t)
    assert [v.status for v in vs] == ["pass"] * 7
    vs = by_stage(verdicts(metrics(rms=0.5, map_errors=(0.3, 12.0), within=85.0, flip=0.2), "fast", t))
    assert vs["capture", "capture.orientation_rms_deg_corrected"].status == "warn"  # 0.25 < 0.5 <= 1
    maps = vs["maps", "maps.*.per_exponent.*.error_vs_truth_accurate_pct"]
    assert maps.status == "fail" and maps.value == 12.0 and "worst of 2" in maps.note  # judged by the worst exponent
    assert vs["frame budget", "session.within_budget_pct"].status == "warn"  # higher is better: 80 <= 85 < 95
    assert vs["AR frames", "session.flip_mean"].status == "fail"


def test_a_figure_zero_by_construction_or_not_measured_is_not_judged():
    vs = by_stage(verdicts(metrics(flip=0.0, lit_by_truth=True), "fast", ReportSection()))
    flip = vs["AR frames", "session.flip_mean"]
    assert flip.status == "n/a" and "by construction" in flip.note
    m = metrics()
    del m["session"]["flip_mean"]
    m["truth"] = {"scenario": "absent: the recording names no scenario"}
    flip = by_stage(verdicts(m, "fast", ReportSection()))["AR frames", "session.flip_mean"]
    assert flip.status == "n/a" and flip.value is None and "not measured" in flip.note


def test_worse_beyond_tolerance_follows_the_better_direction_and_the_floor():
    flip = metric_for("session.flip_mean")
    assert worse_beyond_tolerance(flip, 0.05, 0.07) and not worse_beyond_tolerance(flip, 0.07, 0.05)
    assert not worse_beyond_tolerance(flip, 0.0010, 0.0025)  # beyond 10 % but under the floor
    within = metric_for("session.within_budget_pct")
    assert within.better == HIGHER and worse_beyond_tolerance(within, 99.0, 90.0)
    assert not worse_beyond_tolerance(metric_for("session.frames_total"), 100, 10)  # a count: not judged
    assert not worse_beyond_tolerance(flip, math.nan, 1.0)


def test_labels_units_and_wildcards():
    assert label_of("maps.fast.per_exponent.80.error_vs_truth_accurate_pct").endswith("(fast, s = 80)")
    assert label_of("capture.ape_rot_rmse_deg_corrected") == "APE rotation, corrected (rmse)"
    assert label_of("no.such.figure") == "no.such.figure" and metric_for("no.such.figure") is None
    assert unit_text(metric_for("capture.coverage_pct"), 99.5) == "99.500 %"
    assert unit_text(metric_for("session.frames_lost"), 3.0) == "3 frames"
