"""HDR image files: read OpenEXR and Radiance .hdr, write float32 RGB OpenEXR, .hdr and PNG previews.

Images in memory are float32 arrays (H, W, 3) of linear RGB radiance, row 0 = top. Every write is
atomic (core.files.atomic_path). Read errors become one-line ArsimErrors; the C libraries' own
messages on stderr are captured and folded into that line instead of being printed.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import OpenEXR

from arsim.core.errors import ArsimError
from arsim.core.files import atomic_path

__all__ = [
    "NONFINITE_POLICIES",
    "read_hdr",
    "replace_nonfinite",
    "tonemap_preview",
    "write_exr",
    "write_hdr",
    "write_image",
    "write_png_preview",
]

HDR_SUFFIXES = (".exr", ".hdr")
NONFINITE_POLICIES = ("refuse", "zero")

# The largest image read: 16384 x 8192 (a "16k" HDRI), 1.5 GiB as float32 RGB; a header claiming more
# is refused before the decoder allocates it.
MAX_PIXELS = 16384 * 8192

_EXR_MAGIC = b"\x76\x2f\x31\x01"
_RADIANCE_MAGIC = b"#?"
_LIBC = ctypes.CDLL(None)
_LDR_MAGICS = {b"\x89PNG": "PNG", b"\xff\xd8\xff": "JPEG", b"BM": "BMP", b"GIF8": "GIF"}


@contextlib.contextmanager
def _captured_output() -> Iterator[list[str]]:
    """Capture what libraries print while reading into a list of lines, so that a failed read ends in
    one clean message: OpenEXR's binding reports some errors on Python's stdout, its C core on fd 2."""
    lines: list[str] = []
    py_sink = io.StringIO()
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    with tempfile.TemporaryFile() as sink:
        for fd in saved:
            os.dup2(sink.fileno(), fd)
        try:
            with contextlib.redirect_stdout(py_sink), contextlib.redirect_stderr(py_sink):
                yield lines
        finally:
            _LIBC.fflush(None)  # C and C++ streams buffer stdout when it is not a terminal
            for fd, copy in saved.items():
                os.dup2(copy, fd)
                os.close(copy)
            sink.seek(0)
            text = py_sink.getvalue() + sink.read().decode("utf-8", "replace")
            lines.extend(line.strip() for line in text.splitlines())


def _file_kind(path: Path) -> str:
    """'exr' or 'hdr' by the file's first bytes; anything else is an error naming what it is."""
    if not path.exists():
        raise ArsimError(f"{path}: no such file; check the path")
    if not path.is_file():
        raise ArsimError(f"{path}: is not a file; give an .exr or .hdr image")
    with path.open("rb") as f:
        head = f.read(16)
    if head.startswith(_EXR_MAGIC):
        return "exr"
    if head.startswith(_RADIANCE_MAGIC):
        return "hdr"
    for magic, name in _LDR_MAGICS.items():
        if head.startswith(magic):
            raise ArsimError(f"{path}: is an 8-bit {name} image, not HDR; give an OpenEXR (.exr) or Radiance (.hdr) file")
    raise ArsimError(f"{path}: is not an HDR image (neither OpenEXR nor Radiance .hdr); give an .exr or .hdr file")


def _rgb_from_exr_channels(channels: dict, path: Path) -> np.ndarray:
    for group in ("RGB", "RGBA"):
        if group in channels:
            return np.asarray(channels[group].pixels)[..., :3]
    if all(c in channels for c in "RGB"):
        return np.stack([np.asarray(channels[c].pixels) for c in "RGB"], axis=-1)
    if "Y" in channels:
        return np.repeat(np.asarray(channels["Y"].pixels)[..., None], 3, axis=-1)
    names = ", ".join(sorted(channels)) or "none"
    raise ArsimError(f"{path}: has no R, G, B (or Y) channels (it has: {names}); save it as RGB")


def _read_exr(path: Path) -> np.ndarray:
    failure = None
    with _captured_output() as captured:
        try:
            channels = OpenEXR.File(str(path)).channels()
        except Exception as exc:  # RuntimeError, ValueError, ... for damaged files
            failure = str(exc)
    # The library may also print an error and still return partly filled pixels: never trust those.
    printed = [line for line in captured if "EXR_ERR" in line or "Exception" in line]
    if failure is not None or printed:
        reason = ([line for line in printed if "EXR_ERR" in line] or printed or [failure])[-1]
        reason = reason.split(": ", 1)[-1]
        raise ArsimError(f"{path}: is a truncated or corrupt OpenEXR file ({reason}); re-export it")
    return _rgb_from_exr_channels(channels, path)


def _radiance_size(path: Path) -> tuple[int, int]:
    """(height, width) from a Radiance file's resolution line (after the header's blank line), refused in
    one line when missing, absurd or more than the file's bytes can hold (a scanline takes 4 bytes at least)."""
    with path.open("rb") as f:
        head = f.read(65536)
    end = head.find(b"\n\n")
    line_end = head.find(b"\n", end + 2) if end >= 0 else -1
    fields = head[end + 2:line_end].split() if line_end > 0 else []
    if len(fields) != 4 or fields[0] not in (b"-Y", b"+Y", b"-X", b"+X") or not (fields[1] + fields[3]).isdigit():
        raise ArsimError(f"{path}: has no Radiance resolution line (such as -Y 512 +X 1024) after its header; re-export it")
    first, second = int(fields[1]), int(fields[3])
    height, width = (first, second) if fields[0].endswith(b"Y") else (second, first)
    if height * width > MAX_PIXELS or height * width == 0:
        raise ArsimError(f"{path}: its header gives {width} x {height} pixels; arsim reads images of 1 to "
                         f"{MAX_PIXELS:,} pixels (16384 x 8192): resize it")
    data_bytes = path.stat().st_size - line_end - 1
    if data_bytes < 4 * height:
        raise ArsimError(f"{path}: is truncated ({data_bytes} bytes of pixels for {height} scanlines); re-export it")
    return height, width


def _read_radiance(path: Path) -> np.ndarray:
    _radiance_size(path)
    with _captured_output():
        bgr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if bgr is None or bgr.ndim != 3 or bgr.shape[2] < 3:
        raise ArsimError(f"{path}: is a truncated or corrupt Radiance .hdr file; re-export it")
    return bgr[..., 2::-1]


def read_hdr(path: str | os.PathLike) -> np.ndarray:
    """Linear RGB radiance (H, W, 3) float32 from an OpenEXR (half or float; RGB, RGBA, or R/G/B or Y
    channels) or Radiance .hdr file. Non-finite texels are kept; see replace_nonfinite."""
    path = Path(path)
    kind = _file_kind(path)
    rgb = _read_exr(path) if kind == "exr" else _read_radiance(path)
    if rgb.shape[0] == 0 or rgb.shape[1] == 0:
        raise ArsimError(f"{path}: the image is empty (0 pixels)")
    return np.ascontiguousarray(rgb, dtype=np.float32)


def replace_nonfinite(image: np.ndarray, policy: str, name: str = "image",
                      fix: str = "pass --nan zero to replace them with 0") -> tuple[np.ndarray, int]:
    """Apply the NaN/Inf policy: 'refuse' raises if any texel is NaN or Inf (the error says `fix`: how the
    caller's user replaces them), 'zero' sets those texels (all channels of them) to 0. Returns the image
    and the number of texels replaced."""
    if policy not in NONFINITE_POLICIES:
        raise ArsimError(f"NaN/Inf policy {policy!r} is unknown; use one of {', '.join(NONFINITE_POLICIES)}")
    bad = ~np.isfinite(image).all(axis=-1)
    count = int(bad.sum())
    if count == 0:
        return image, 0
    if policy == "refuse":
        raise ArsimError(f"{name}: {count} texels are NaN or Inf; fix the source, or {fix}")
    out = image.copy()
    out[bad] = 0.0
    return out, count


def write_exr(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write (H, W, 3) radiance as a float32 RGB OpenEXR (ZIP compression), atomically."""
    rgb = np.ascontiguousarray(np.asarray(image)[..., :3], dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        OpenEXR.File(header, {"RGB": rgb}).write(str(tmp))


def write_hdr(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write (H, W, 3) radiance as a Radiance .hdr (RGBE), atomically."""
    bgr = np.ascontiguousarray(np.asarray(image, dtype=np.float32)[..., 2::-1])
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), bgr):
            raise ArsimError(f"{path}: could not be written as Radiance .hdr")


def tonemap_preview(image: np.ndarray, key: float = 0.18) -> np.ndarray:
    """8-bit sRGB preview of linear radiance with Reinhard's global operator (photographic key `key`).

    The log-average luminance is taken over pixels with positive luminance, so the black outside an
    angle map's disk does not darken the rest; L_white is the brightest scaled luminance, so the
    brightest texel just reaches white.
    """
    rgb = np.nan_to_num(np.asarray(image, dtype=np.float64)[..., :3], nan=0.0, posinf=0.0, neginf=0.0)
    rgb = np.maximum(rgb, 0.0)
    lum = rgb @ np.array([0.2126, 0.7152, 0.0722])
    lit = lum > 0
    if not lit.any():
        return np.zeros(rgb.shape, dtype=np.uint8)
    log_avg = np.exp(np.mean(np.log(lum[lit] + 1e-12)))
    scaled = key / log_avg * lum
    white = max(float(scaled.max()), 1e-6)
    mapped = scaled * (1.0 + scaled / white**2) / (1.0 + scaled)
    ratio = np.divide(mapped, lum, out=np.zeros_like(lum), where=lit)
    display = np.clip(rgb * ratio[..., None], 0.0, 1.0)
    srgb = np.where(display <= 0.0031308, 12.92 * display, 1.055 * display ** (1 / 2.4) - 0.055)
    return np.round(srgb * 255.0).astype(np.uint8)


def write_png_preview(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write a tone-mapped 8-bit PNG preview of linear radiance, atomically."""
    rgb8 = tonemap_preview(image)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(rgb8[..., ::-1])):
            raise ArsimError(f"{path}: could not be written as PNG")


def write_image(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write by suffix: .exr (float32 RGB), .hdr (RGBE) or .png (tone-mapped preview)."""
    suffix = Path(path).suffix.lower()
    writers = {".exr": write_exr, ".hdr": write_hdr, ".png": write_png_preview}
    if suffix not in writers:
        raise ArsimError(f"{path}: unknown output type {suffix or '(none)'}; use .exr, .hdr or .png")
    writers[suffix](path, image)
