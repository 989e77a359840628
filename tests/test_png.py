"""arsim's PNG writer: OpenCV (libpng) reads back every pixel, at every level."""

import cv2
import numpy as np
import pytest

from arsim.core.png import png_bytes


@pytest.mark.parametrize("level", [1, 3])
@pytest.mark.parametrize("shape", [(480, 640, 3), (7, 5, 3), (9, 4), (3, 1, 3)])
def test_png_round_trips_through_opencv(level, shape):
    image = np.random.default_rng(sum(shape) + level).integers(0, 256, shape, dtype=np.uint8)
    decoded = cv2.imdecode(np.frombuffer(png_bytes(image, level), np.uint8), cv2.IMREAD_UNCHANGED)
    if image.ndim == 3:
        decoded = decoded[..., ::-1]  # OpenCV gives BGR
    assert decoded.dtype == np.uint8 and np.array_equal(decoded, image)


def test_noisy_camera_frames_compress():
    x = np.linspace(0, 255, 640)[None, :, None] + np.random.default_rng(0).normal(0, 3, (480, 640, 3))
    frame = np.clip(x, 0, 255).astype(np.uint8)  # a smooth, noisy picture like a camera frame
    assert len(png_bytes(frame)) < 0.75 * frame.size


@pytest.mark.parametrize("view", ["rgb of rgba", "mirrored", "every other row and third pixel", "bgr", "one channel"])
def test_png_of_strided_views_equals_their_copies(view):
    """Frames read back from GL are the RGB of RGBA rows; the writer reads such views in place."""
    rgba = np.random.default_rng(5).integers(0, 256, (48, 64, 4), dtype=np.uint8)
    image = {"rgb of rgba": rgba[..., :3], "mirrored": rgba[:, ::-1, :3], "every other row and third pixel": rgba[::2, 1::3, :3],
             "bgr": rgba[..., 2::-1], "one channel": rgba[..., 1]}[view]
    assert png_bytes(image) == png_bytes(np.ascontiguousarray(image))
    decoded = cv2.imdecode(np.frombuffer(png_bytes(image), np.uint8), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(decoded[..., ::-1] if image.ndim == 3 else decoded, image)
