"""The AR session measured: its tracked poses against the truth, its frames' scores against the truth
frames, and the render loop's step timings, as the figures `metrics.json` reports."""

from __future__ import annotations

import numpy as np

from arsim.evaluate.profile import step_gl_figures
from arsim.evaluate.tracking import TrackingRun, measure_poses
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
