"""The true environment of a scenario, as the angle map every later stage measures against."""

from __future__ import annotations

import numpy as np

from arsim.core.conventions import yaw_rotation
from arsim.core.hdr_io import read_hdr, replace_nonfinite
from arsim.core.resample import detect_layout, to_layout
from arsim.scenario.sections import EnvironmentSection


def read_environment(section: EnvironmentSection) -> np.ndarray:
    """The [environment] map as read, checked (finite, 1:1 or 2:1): what `arsim validate` checks and every
    stage reads.

    Non-finite texels are refused: a ground truth with NaN in it would poison every metric."""
    image, _ = replace_nonfinite(read_hdr(section.map), "refuse", f"[environment] map {section.map}",
                                 "replace them with `arsim convert IN OUT --nan zero` and give OUT as [environment] map")
    detect_layout(image, f"[environment] map {section.map}")
    return image


def load_environment(section: EnvironmentSection) -> np.ndarray:
    """The [environment] map as a probe_size² float32 angle map, turned by yaw_deg, scaled by intensity."""
    image = read_environment(section)
    rotation = yaw_rotation(section.yaw_deg) if section.yaw_deg else None
    probe = to_layout(image, "anglemap", section.probe_size, rotation)
    return probe * np.float32(section.intensity)
