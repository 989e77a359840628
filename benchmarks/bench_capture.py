"""Capture speed on a recording, against the floor of decoding its frames once (prints figures; not a test).

    python benchmarks/bench_capture.py [--recording DIR] [--align-every K]

Without --recording it records the default scenario's sweep (AR path off) into a temporary folder first.
In the same run: the frames decoded once (two reader threads, as the capture reads them: the floor any
capture of PNG frames pays), the capture without the refinement (the online pass alone) and with it
(the online pass, the refinement's solve, and the second accumulation pass). Prints frames per second,
the split between the online pass and the refinement, the ratio of each to the decoding floor, and the
orientation error of each.
"""

import argparse
import dataclasses
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from arsim.capture.pipeline import CaptureSettings, capture, recording_scenario

from arsim.core.png import read_frame
from arsim.sensors.recording import load_recording


def rms_deg(estimate, truth) -> float:
    e = np.degrees((estimate.inv() * truth).magnitude())
    return float(np.sqrt(np.mean(e**2)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="example:\n  python benchmarks/bench_capture.py --recording rec\n"
                                            "  (rec: `arsim record -o rec`, or the recording of a run with --keep-recording)")
    parser.add_argument("--recording", type=Path, metavar="DIR", help="a recording (default: record the default sweep)")
    parser.add_argument("--align-every", type=int, help="metered frames between alignments (default: the scenario's)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.recording
        if folder is None:
            scenario = Path(tmp) / "sweep.toml"
            scenario.write_text("[ar]\nenabled = false\n")
            folder = Path(tmp) / "rec"
            subprocess.run([sys.executable, "-m", "arsim.cli", "record", "-o", str(folder), str(scenario)], check=True,
                           capture_output=True)
        rec = load_recording(folder)
        settings = CaptureSettings.of(recording_scenario(rec), align_every=args.align_every)
        start = time.perf_counter()
        with ThreadPoolExecutor(2) as readers:
            for _ in readers.map(read_frame, [rec.folder / f["file"] for f in rec.frames]):
                pass
        decode = time.perf_counter() - start
        online = capture(rec, dataclasses.replace(settings, refine=False))
        refined = capture(rec, dataclasses.replace(settings, refine=True))
        n = len(rec.frames)
        print(f"{n} frames {rec.frames and recording_scenario(rec).device.camera.width}x"
              f"{recording_scenario(rec).device.camera.height} into a {settings.size}² probe, alignment every "
              f"{settings.align_every} metered frame(s)")
        print(f"  decoding the frames once (the floor): {decode:6.1f} s  {n / decode:6.1f} frames/s")
        print(f"  online pass alone:                    {online.seconds:6.1f} s  {online.frames_per_second:6.1f} frames/s  "
              f"{online.seconds / decode:4.2f}x the floor  orientation RMS {rms_deg(online.corrected, online.truth):.3f} deg")
        split = refined.seconds - refined.seconds_online
        print(f"  with the refinement:                  {refined.seconds:6.1f} s  {refined.frames_per_second:6.1f} frames/s  "
              f"{refined.seconds / decode:4.2f}x the floor  orientation RMS {rms_deg(refined.corrected, refined.truth):.3f} deg")
        print(f"    split: online pass {refined.seconds_online:.1f} s, refinement {split:.1f} s "
              f"(online : refinement = 1 : {split / refined.seconds_online:.2f}; of the refinement, features, matching "
              f"and the solve {refined.refinement.seconds:.1f} s, the second accumulation pass "
              f"{split - refined.refinement.seconds:.1f} s); "
              f"{len(refined.refinement.keyframes)} keyframes, {refined.refinement.loop_closures} pairs used")


if __name__ == "__main__":
    main()
