"""Tag tracking per detector, alone and fused with the IMU, on the default AR path and on lost_tag's
(prints figures and writes benchmarks/results/bench_tracking.json; not a test): detection rate where the
tag is fully in view, the camera's rotation error (degrees) and position error (percent of its distance to
the tag), p50 and p95, overall and by distance band, the tracker's CPU time per frame (640 x 480, one
thread, frames decoded beforehand), and the fused poses drawn without the tag (extrapolated): how many,
for how long at most, their errors. Each on the same frames in one process.

    python benchmarks/bench_tracking.py                 # records both scenarios into a temporary folder
    python benchmarks/bench_tracking.py --keep /tmp/bt  # ... into that folder, kept (reused when there)
"""

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from arsim.capture.pipeline import burst_response, recording_scenario
from arsim.core.png import read_frame
from arsim.core.tags import DETECTORS
from arsim.evaluate.tracking import measure_poses
from arsim.scenario import load_scenario
from arsim.sensors.camera import SensorSettings
from arsim.sensors.frames import frame_positions
from arsim.sensors.recording import load_recording, record
from arsim.tracking.fusion import recording_tracker

RESULTS = Path(__file__).resolve().parent / "results"
SCENARIOS = ("default", "lost_tag")
BANDS = ((0.0, 0.7), (0.7, 1.1), (1.1, 10.0))  # metres from the tag


def recording(name: str, folder: Path):
    path = folder / name
    if not (path / "ar" / "meta.json").exists():
        record(load_scenario(None if name == "default" else name), path)
    sweep = load_recording(path)
    linear = burst_response(sweep, SensorSettings.of(recording_scenario(sweep).device.camera)).linear[:, 1]
    return load_recording(path / "ar"), linear


def stats(values: np.ndarray) -> dict:
    if not len(values):
        return {"p50": None, "p95": None, "frames": 0}
    return {"p50": float(np.percentile(values, 50)), "p95": float(np.percentile(values, 95, method="higher")), "frames": int(len(values))}


def evaluate(rec, linear, detector: str, fusion: bool, frames: list) -> dict:
    recording_tracker(rec, linear, detector, False).track(frames[0])  # (warm up)
    tracker = recording_tracker(rec, linear, detector, fusion)
    poses, ms = [], []
    for k, frame in enumerate(frames):
        start = time.perf_counter()
        poses.append(tracker.track(frame, k))
        ms.append(1000 * (time.perf_counter() - start))
    run = measure_poses(rec, poses)
    distance = np.linalg.norm(frame_positions(rec), axis=1)
    seen = run.visible
    out = {"detection_rate_visible": float(run.found[seen].mean()), "found_while_not_visible": int((run.found & ~seen).sum()),
           "rotation_deg": stats(run.rot_err_deg[seen]), "position_pct": stats(run.trans_err_pct[seen]),
           "ms_per_frame": stats(np.array(ms)), "bands": {},
           "extrapolated": {k: v for k, v in run.metrics().items() if k.startswith(("frames_extrapolated", "extrapolated"))}}
    for low, high in BANDS:
        band = seen & (distance >= low) & (distance < high)
        out["bands"][f"{low:g}-{high:g} m"] = {"rotation_deg": stats(run.rot_err_deg[band]), "position_pct": stats(run.trans_err_pct[band])}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--keep", type=Path, help="record into this folder (and reuse what is there)")
    args = parser.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="bench-tracking-"))
    folder.mkdir(parents=True, exist_ok=True)
    results = {}
    for name in SCENARIOS:
        rec, linear = recording(name, folder)
        frames = [read_frame(rec.folder / f["file"]) for f in rec.frames]
        results[name] = {f"{d}{' + IMU' if fusion else ''}": evaluate(rec, linear, d, fusion, frames)
                         for d in DETECTORS for fusion in (False, True)}
        print(f"{name}: {len(frames)} frames")
        print(f"  {'tracker':<16} {'found':>6} {'rot p50':>8} {'rot p95':>8} {'pos% p50':>9} {'pos% p95':>9} {'ms p50':>7}   "
              + "   ".join(f"{b}: rot/pos p95" for b in next(iter(results[name].values()))["bands"])
              + "   extrapolated: frames, s max, rot/pos p95")
        for d, r in results[name].items():
            bands = "   ".join(f"{v['rotation_deg']['p95'] or float('nan'):.3f} / {v['position_pct']['p95'] or float('nan'):.3f}"
                               for v in r["bands"].values())
            x = r["extrapolated"]
            print(f"  {d:<16} {r['detection_rate_visible']:6.3f} {r['rotation_deg']['p50']:8.3f} {r['rotation_deg']['p95']:8.3f} "
                  f"{r['position_pct']['p50']:9.3f} {r['position_pct']['p95']:9.3f} {r['ms_per_frame']['p50']:7.2f}   {bands}   "
                  f"{x['frames_extrapolated']}, {x['extrapolated_s_max']:.2f}, {x['extrapolated_rot_err_deg_p95'] or 0:.3f} / "
                  f"{x['extrapolated_trans_err_pct_p95'] or 0:.3f}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "bench_tracking.json").write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {RESULTS / 'bench_tracking.json'}")


if __name__ == "__main__":
    main()
