"""The light estimators' cost per frame (prints figures; not a test): the single-frame estimator on each
frame of a sweep (640 x 480), and the capture's estimate from each of its probe snapshots (32², one about
every second of the sweep, so its cost per frame is a thirtieth of it at 30 frames/s); beside them in the same
run, a floor: converting the frame to floats (what any per-frame image work pays).

    python benchmarks/bench_estimate.py [--recording REC]   # default: records the quick scenario's sweep
"""

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from arsim.capture.pipeline import CaptureSettings, capture, exposure_scales, fused_camera_orientations, recording_scenario
from arsim.core.png import read_frame
from arsim.estimate.shapes import estimate_light
from arsim.estimate.single_frame import SingleFrameEstimator
from arsim.scenario import load_scenario
from arsim.sensors.camera import SensorSettings
from arsim.sensors.frames import recording_camera
from arsim.sensors.recording import load_recording, record


def median_ms(fn, items) -> float:
    times = []
    for item in items:
        start = time.perf_counter()
        fn(item)
        times.append(1000 * (time.perf_counter() - start))
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--recording", type=Path, help="a recording's folder (default: the quick scenario's, recorded)")
    args = parser.parse_args()
    if args.recording is None:
        args.recording = Path(tempfile.mkdtemp(prefix="bench-estimate-")) / "rec"
        scenario = load_scenario("quick")
        import dataclasses

        record(dataclasses.replace(scenario, ar=dataclasses.replace(scenario.ar, enabled=False)), args.recording)
    rec = load_recording(args.recording)
    result = capture(rec, CaptureSettings.of(recording_scenario(rec)))
    frames = [read_frame(rec.folder / f["file"]) for f in rec.frames]
    scales = exposure_scales(rec, SensorSettings.of(recording_scenario(rec).device.camera))
    views = fused_camera_orientations(rec).as_matrix()
    estimator = SingleFrameEstimator(recording_camera(rec))
    single = median_ms(lambda k: estimator.estimate(frames[k], result.response.linear / scales[k], views[k]), range(len(frames)))
    snapshot = median_ms(lambda s: estimate_light(s[1]), result.snapshots)
    floor = median_ms(lambda k: frames[k].astype(np.float32), range(len(frames)))
    fps = rec.meta["camera"]["fps"]
    print(f"{len(frames)} frames of {frames[0].shape[1]} x {frames[0].shape[0]}, {len(result.snapshots)} snapshots")
    print(f"single frame: {single:.3f} ms a frame ({single / floor:.1f} x the floor)")
    print(f"capture: {snapshot:.3f} ms a snapshot, {snapshot * len(result.snapshots) / len(frames):.3f} ms a frame at {fps:g} "
          f"frames/s ({snapshot * len(result.snapshots) / len(frames) / floor:.2f} x the floor)")
    print(f"floor (the frame to float32): {floor:.3f} ms")


if __name__ == "__main__":
    main()
