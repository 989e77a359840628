"""Capture speed and quality on a recording (prints figures; not a test).

    python benchmarks/bench_capture.py [--recording DIR] [--align-every K]

Without --recording it records the default scenario's sweep (AR path off) into a temporary folder
first. Prints frames per second (frame reading, alignment and accumulation into the 512² angle map
included) and the orientation error with and without the correction.
"""

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from arsim.capture.pipeline import CaptureSettings, capture, recording_scenario
from arsim.sensors.recording import load_recording


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--recording", type=Path)
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
        result = capture(rec, settings)
        def rms(a):
            e = np.degrees((a.inv() * result.truth).magnitude())
            return float(np.sqrt(np.mean(e**2)))
        print(f"{len(result.t_s)} frames in {result.seconds:.1f} s: {result.frames_per_second:.1f} frames/s "
              f"({result.accumulator.size}² probe, alignment every {settings.align_every} metered frame(s), "
              f"{int(result.aligned.sum())} succeeded)")
        print(f"orientation error RMS: {rms(result.corrected):.3f} degrees corrected, {rms(result.uncorrected):.3f} uncorrected; "
              f"coverage {100 * result.accumulator.coverage():.2f} %")


if __name__ == "__main__":
    main()
