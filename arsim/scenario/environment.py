"""The true environment of a scenario, as the angle map every later stage measures against."""

from __future__ import annotations

import numpy as np

from arsim.core.conventions import yaw_rotation
from arsim.core.hdr_io import read_hdr, replace_nonfinite
from arsim.core.resample import to_layout
from arsim.scenario.sections import EnvironmentSection


def load_environment(section: EnvironmentSection) -> np.ndarray:
    """The [environment] map as a probe_size² float32 angle map, turned by yaw_deg, scaled by intensity.

    Non-finite texels are refused: a ground truth with NaN in it would poison every metric."""
    image, _ = replace_nonfinite(read_hdr(section.map), "refuse", f"[environment] map {section.map}",
                                 "replace them with `arsim convert IN OUT --nan zero` and give OUT as [environment] map")
    rotation = yaw_rotation(section.yaw_deg) if section.yaw_deg else None
    probe = to_layout(image, "anglemap", section.probe_size, rotation)
    return probe * np.float32(section.intensity)
