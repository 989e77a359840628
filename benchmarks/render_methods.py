"""FLIP of the AR session against the truth frames, per map method, on one recording and its captured
probe (prints a table; not a test).

    python benchmarks/render_methods.py --recording DIR [--every K] [--map-size N] [--methods fast,sh,...]

DIR is a recording with an AR path (e.g. `arsim record -o rec`, or the recording/ folder `arsim render`
writes). The probe is captured once from its sweep; each method then bakes the session's maps from it
(and from the true environment, for the truth frames) and the session runs over every K-th frame.
"""

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from arsim.capture.pipeline import CaptureSettings, capture, recording_scenario
from arsim.core.resample import to_layout
from arsim.capture.accumulate import filled
from arsim.render.content import scene_objects
from arsim.evaluate.flip import masked_flip
from arsim.render.session import SessionSettings, maps_needed, run_session, session_maps
from arsim.scenario.environment import load_environment
from arsim.sensors.recording import load_recording


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--recording", type=Path, required=True)
    parser.add_argument("--every", type=int, default=10)
    parser.add_argument("--map-size", type=int, default=128)
    parser.add_argument("--methods", default="fast,mipmap,sh,mc,accurate")
    args = parser.parse_args()
    sweep, ar = load_recording(args.recording), load_recording(args.recording / "ar")
    scenario = recording_scenario(sweep)
    result = capture(sweep, CaptureSettings.of(scenario))
    probe = to_layout(filled(result.accumulator.probe(), result.accumulator.covered()), "anglemap", args.map_size)
    truth = load_environment(dataclasses.replace(scenario.environment, probe_size=args.map_size))
    print(f"{args.recording}: every {args.every}th of {len(ar.frames)} AR frames, {args.map_size}² maps")
    print("| method | FLIP mean (captured probe) | FLIP max frame | seconds |")
    print("|---|---|---|---|")
    for method in args.methods.split(","):
        start = time.perf_counter()
        objects = scene_objects(scenario.render)
        needed = maps_needed(objects, method)
        with tempfile.TemporaryDirectory() as tmp:
            session = run_session(ar, result.response.linear[:, 1], session_maps(probe, needed), session_maps(truth, needed),
                                  Path(tmp), objects, masked_flip, SessionSettings(method, every=args.every))
        flip = session.flip[np.isfinite(session.flip)]
        print(f"| {method} | {flip.mean():.4f} | {flip.max():.4f} | {time.perf_counter() - start:.0f} |")


if __name__ == "__main__":
    main()
