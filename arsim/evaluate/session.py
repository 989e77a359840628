"""The AR session measured: its tracked poses against the truth, its frames' scores against the truth
frames, and the render loop's step timings, as the figures `metrics.json` reports."""

from __future__ import annotations

import numpy as np

from arsim.evaluate.profile import step_gl_figures
from arsim.evaluate.tracking import TrackingRun, measure_poses
from arsim.lighting.mapset import MapSet
from arsim.render.session import SessionResult
from arsim.sensors.frames import NO_SCENARIO
from arsim.sensors.recording import Recording


def session_metrics(rec: Recording, session: SessionResult) -> tuple[TrackingRun, dict]:
    """The session's tracking against the truth (rec: the AR recording it ran over), and its figures. What needs
    a truth the recording lacks is absent, and "truth" says why: the tracking's errors without a ground truth,
    the FLIP against the truth frames where the true environment is unknown (the session was not scored)."""
    tracking = measure_poses(rec, session.poses, session.frames)
    figures = tracking.metrics()
    absent = figures.pop("truth", {})
    drawn = np.isfinite(session.flip)
    if session.scored:
        figures |= {"flip_mean": float(np.mean(session.flip[drawn])) if drawn.any() else float("nan"),
                    "flip_frames": int(drawn.sum())}
    figures["frames_rendered"] = [int(k) for k in session.frames]
    if session.scored:
        figures["flip_per_frame"] = [None if not np.isfinite(f) else float(f) for f in session.flip]
    else:
        absent["scenario"] = NO_SCENARIO
    figures |= {"step_ms": {name: float(np.median(v)) for name, v in session.step_ms.items() if v}} | step_gl_figures(session.records)
    return tracking, figures | ({"truth": absent} if absent else {})


def lit_by_truth(maps: dict[str, MapSet], truth_maps: dict[str, MapSet] | None) -> bool:
    """Whether the objects were lit by the true environment's own maps (every map equal to the truth's): then the
    truth frame is the frame and its FLIP is 0 by construction, not a result (e.g. `arsim render --env` of the
    scenario's own environment)."""
    if not truth_maps or set(maps) - set(truth_maps):
        return False
    return all(set(m.maps) <= set(truth_maps[name].maps) and
               all(np.array_equal(a, truth_maps[name].maps[s]) for s, a in m.maps.items()) for name, m in maps.items())
