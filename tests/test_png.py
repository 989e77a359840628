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


@pytest.mark.parametrize("shape", [(480, 640, 3), (7, 5, 3), (3, 1, 3), (6, 4)])
def test_read_frame_unfilters_arsims_frames_as_opencv_decodes_them(tmp_path, shape):
    """read_frame unfilters a frame laid out as png_bytes writes it from the data its check inflated, and
    hands any other PNG (grey; rows without the Sub filter) to OpenCV: the pixels are OpenCV's either way."""
    import struct
    import zlib

    from arsim.core.png import _parsed, _written_here, read_frame

    image = np.random.default_rng(sum(shape)).integers(0, 256, shape, dtype=np.uint8)
    ours, plain = tmp_path / "ours.png", tmp_path / "plain.png"
    ours.write_bytes(png_bytes(image))
    # the same image with every row unfiltered (filter type 0), as other writers may store it
    rows = np.hstack([np.zeros((shape[0], 1), np.uint8), image.reshape(shape[0], -1)])
    header = struct.pack(">IIBBBBB", shape[1], shape[0], 8, 2 if image.ndim == 3 else 0, 0, 0, 0)
    chunk = lambda kind, data: struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    plain.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows.tobytes()))
                      + chunk(b"IEND", b""))
    for path, fast in ((ours, image.ndim == 3), (plain, False)):
        _, header, pixels = _parsed(path.read_bytes())
        assert (_written_here(header, pixels) is not None) == fast
        expected = np.repeat(image[..., None], 3, axis=-1) if image.ndim == 2 else image
        assert np.array_equal(read_frame(path), expected)
        rgba = read_frame(path, alpha=True)  # (what the render loop uploads as it is)
        assert rgba.shape == (*expected.shape[:2], 4)
        assert np.array_equal(rgba[..., :3], expected) and (rgba[..., 3] == 255).all()


def test_kept_frames_are_the_files_pixels_until_a_file_changes(tmp_path):
    """While a run keeps the frames it writes, read_frame gives them from memory: the same pixels as the file,
    read-only (every reader shares them), and only while the file is the one written: a file replaced, changed or
    removed is read from disk. Past the limit, and outside kept_frames, nothing is kept."""
    import os

    from arsim.core.png import _KEPT, kept_frames, read_frame, write_frame_png

    rng = np.random.default_rng(3)
    rgba = rng.integers(0, 256, (3, 24, 32, 4), dtype=np.uint8)
    frames = [rgba[k, :, :, :3] for k in range(3)]  # (strided, as GL read-backs are)
    paths = [tmp_path / f"{k}.png" for k in range(3)]
    with kept_frames(2 * frames[0][..., 0].size * 3):  # room for two frames
        for path, frame in zip(paths, frames):
            write_frame_png(path, frame)
        kept = [_KEPT.get(path) for path in paths]
        assert kept[0] is not None and kept[1] is not None and kept[2] is None  # the third past the limit
        for path, frame in zip(paths, frames):
            image = read_frame(path)
            assert image.flags.c_contiguous and np.array_equal(image, frame)
            assert np.array_equal(image, cv2.imdecode(np.frombuffer(path.read_bytes(), np.uint8), cv2.IMREAD_COLOR)[..., ::-1])
        assert read_frame(paths[0]) is kept[0] and not kept[0].flags.writeable
        with pytest.raises(ValueError):
            kept[0][0, 0, 0] = 1
        written = frames[1].copy()
        frames[1][...] = 0  # the writer's array is its own: what is kept does not follow it
        assert np.array_equal(read_frame(paths[1]), written)
        other = np.full((24, 32, 3), 9, np.uint8)  # (smaller as PNG: the file's size changes whatever the clock)
        paths[0].write_bytes(png_bytes(other))  # changed in place (another writer)
        assert np.array_equal(read_frame(paths[0]), other)
        os.replace(paths[2], paths[1])  # replaced by another file
        assert np.array_equal(read_frame(paths[1]), frames[2])
    assert _KEPT.frames == {} and _KEPT.held == 0
    write_frame_png(paths[0], frames[0])
    assert _KEPT.get(paths[0]) is None  # not kept outside kept_frames
