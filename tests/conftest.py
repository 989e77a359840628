from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from arsim.core.assets import assets_dir

ASSETS = assets_dir()
ENVMAPS = sorted((ASSETS / "envmaps").glob("*.exr"))


def write_raw_exr(path: Path, channels: dict[str, np.ndarray]) -> Path:
    """An EXR written straight through OpenEXR (not arsim), to test reading what other tools write."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, channels).write(str(path))
    return path


@pytest.fixture
def gradient() -> np.ndarray:
    """A small 2:1 float32 RGB image with distinct values per texel and channel."""
    h, w = 8, 16
    r = np.arange(h * w, dtype=np.float32).reshape(h, w) / 10
    return np.stack([r, r + 0.5, 2 * r + 0.25], axis=-1)


def pytest_configure(config):
    """The suite's runs use no run cache unless a test names one (--cache): every stage computed, the user's
    cache folder untouched; and show no progress lines (tests that check what a command prints on stderr
    check its messages; tests/test_progress.py turns them on)."""
    import os

    os.environ["ARSIM_CACHE"] = "off"
    os.environ["ARSIM_PROGRESS"] = "off"
