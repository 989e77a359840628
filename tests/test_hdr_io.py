"""HDR files: what OpenEXR and Radiance writers produce is read back exactly; bad files are refused."""

import os

import cv2
import numpy as np
import pytest

from arsim.core.errors import ArsimError
from arsim.core.files import atomic_path
from arsim.core.hdr_io import read_hdr, replace_nonfinite, tonemap_preview, write_exr, write_hdr, write_png_preview
from tests.conftest import ENVMAPS, write_raw_exr


def test_exr_float_rgb_round_trip_is_exact(tmp_path, gradient):
    write_exr(tmp_path / "a.exr", gradient)
    back = read_hdr(tmp_path / "a.exr")
    assert back.dtype == np.float32 and back.shape == gradient.shape
    np.testing.assert_array_equal(back, gradient)


@pytest.mark.parametrize("layout", ["RGB", "RGBA", "R,G,B", "Y"])
@pytest.mark.parametrize("dtype", [np.float16, np.float32])
def test_exr_channel_layouts_and_half_float_are_read(tmp_path, gradient, layout, dtype):
    px = gradient.astype(dtype)
    if layout == "RGB":
        channels = {"RGB": px}
    elif layout == "RGBA":
        channels = {"RGBA": np.concatenate([px, np.ones_like(px[..., :1])], axis=-1)}
    elif layout == "R,G,B":
        channels = {"R": px[..., 0].copy(), "G": px[..., 1].copy(), "B": px[..., 2].copy()}
    else:
        channels = {"Y": px[..., 0].copy()}
    path = write_raw_exr(tmp_path / "in.exr", channels)
    img = read_hdr(path)
    assert img.dtype == np.float32 and img.shape == gradient.shape
    expected = np.repeat(px[..., :1], 3, axis=-1) if layout == "Y" else px
    np.testing.assert_array_equal(img, expected.astype(np.float32))


def test_exr_without_colour_channels_is_refused(tmp_path, gradient):
    path = write_raw_exr(tmp_path / "depth.exr", {"Z": gradient[..., 0].copy()})
    with pytest.raises(ArsimError, match="no R, G, B"):
        read_hdr(path)


def test_radiance_hdr_round_trip_within_rgbe_precision(tmp_path, gradient):
    write_hdr(tmp_path / "a.hdr", gradient + 0.01)
    back = read_hdr(tmp_path / "a.hdr")
    assert back.shape == gradient.shape
    # RGBE keeps 8 mantissa bits of the largest channel: relative error below 2^-7 of that channel.
    np.testing.assert_allclose(back, gradient + 0.01, rtol=0, atol=float((gradient + 0.01).max()) * 2**-7)
    # And channel order is RGB, not OpenCV's BGR.
    assert back[..., 2].mean() > back[..., 0].mean()


def test_radiance_hdr_written_by_opencv_is_read(tmp_path, gradient):
    cv2.imwrite(str(tmp_path / "b.hdr"), gradient[..., ::-1].copy())
    np.testing.assert_allclose(read_hdr(tmp_path / "b.hdr")[..., 2], gradient[..., 2], rtol=2**-7, atol=1e-3)


@pytest.mark.parametrize("path", ENVMAPS, ids=lambda p: p.stem)
def test_every_asset_reads(path):
    img = read_hdr(path)
    assert img.shape == (512, 1024, 3) and np.isfinite(img).all()


def test_missing_file(tmp_path):
    with pytest.raises(ArsimError, match="no such file"):
        read_hdr(tmp_path / "nope.exr")


def test_not_an_image(tmp_path):
    (tmp_path / "notes.exr").write_text("hello, not an image")
    with pytest.raises(ArsimError, match="not an HDR image"):
        read_hdr(tmp_path / "notes.exr")


def test_ldr_image_is_named(tmp_path):
    cv2.imwrite(str(tmp_path / "photo.png"), np.zeros((4, 8, 3), np.uint8))
    with pytest.raises(ArsimError, match="8-bit PNG"):
        read_hdr(tmp_path / "photo.png")


@pytest.mark.parametrize("keep", [0.9, 0.5, 0.1])
def test_truncated_exr_is_refused_quietly(tmp_path, capfd, keep):
    data = ENVMAPS[0].read_bytes()
    (tmp_path / "cut.exr").write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(ArsimError, match="truncated or corrupt"):
        read_hdr(tmp_path / "cut.exr")
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # the library's own messages are folded into the error


def test_corrupt_exr_is_refused(tmp_path):
    data = bytearray(ENVMAPS[0].read_bytes())
    data[400:4000] = os.urandom(3600)
    (tmp_path / "bad.exr").write_bytes(bytes(data))
    with pytest.raises(ArsimError, match="truncated or corrupt"):
        read_hdr(tmp_path / "bad.exr")


def test_nonfinite_texels_are_refused_or_replaced(gradient):
    img = gradient.copy()
    img[0, 0, 1] = np.nan
    img[2, 3] = np.inf
    img[4, 5, 0] = -np.inf
    with pytest.raises(ArsimError, match="3 texels are NaN or Inf.*--nan zero"):
        replace_nonfinite(img, "refuse")
    fixed, count = replace_nonfinite(img, "zero")
    assert count == 3 and np.isfinite(fixed).all()
    assert np.all(fixed[0, 0] == 0) and np.all(fixed[2, 3] == 0)
    np.testing.assert_array_equal(fixed[1], gradient[1])


def test_failed_write_leaves_nothing_behind(tmp_path, gradient):
    target = tmp_path / "out.exr"
    write_exr(target, gradient)
    before = target.read_bytes()
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half a file")
            raise RuntimeError("interrupted")
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]


def test_writes_leave_no_temporary_files(tmp_path, gradient):
    write_exr(tmp_path / "a.exr", gradient)
    write_hdr(tmp_path / "a.hdr", gradient)
    write_png_preview(tmp_path / "a.png", gradient)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "a.hdr", "a.png"]
    assert oct((tmp_path / "a.exr").stat().st_mode & 0o777) != oct(0o600)


def test_preview_tone_map_is_monotonic_and_keeps_black():
    ramp = np.geomspace(1e-3, 1e4, 64, dtype=np.float32)
    img = np.zeros((2, 65, 3), dtype=np.float32)
    img[:, 1:] = ramp[None, :, None]
    out = tonemap_preview(img)
    assert out.dtype == np.uint8
    assert np.all(out[:, 0] == 0)
    assert np.all(np.diff(out[0, 1:, 0].astype(int)) >= 0)
    assert out[0, -1, 0] == 255  # the brightest texel reaches white
    assert tonemap_preview(np.zeros((4, 4, 3))).max() == 0
