"""Fast lossless PNG writing for camera frames, and their reading.

A 640 x 480 noisy frame takes 11-23 ms through libpng (OpenCV, imagecodecs) on this class of CPU,
which alone would use a third of a recording's time budget. The PNG container is four chunks, so
arsim writes it itself and lets ISA-L (isal) do the deflate, at about 4 ms per frame and within a few
percent of libpng's size. Every row uses the Sub filter, which suits noisy photographs; a compiled
loop applies it straight from a strided view (such as the RGB of an RGBA read-back), as a copy to
contiguous RGB alone would cost half as much as the deflate. Files are read back with OpenCV (pixel
for pixel in the tests), after a check of their chunks and image data here: libpng prints its own lines
on standard error for a corrupted file, which would break a refusal's one line.
"""

from __future__ import annotations

import collections
import struct
from collections.abc import Iterable, Iterator
from pathlib import Path

import cv2
import numba
import numpy as np
from isal import isal_zlib

from arsim.core.errors import ArsimError

SIGNATURE = b"\x89PNG\r\n\x1a\n"
SUB_FILTER = 1


@numba.njit(cache=True, nogil=True)
def _sub_filtered(flat: np.ndarray, row_step: int, pixel_step: int, channels: int, out: np.ndarray) -> None:
    """PNG scanlines (H, 1 + W C) of an image whose channel c of pixel (y, x) is the byte
    flat[y row_step + x pixel_step + c]: a filter byte, then each byte minus the same channel of the
    pixel before (modulo 256)."""
    height, width = out.shape[0], (out.shape[1] - 1) // channels
    for y in range(height):
        r = y * row_step
        out[y, 0] = SUB_FILTER
        for c in range(channels):
            out[y, 1 + c] = flat[r + c]
        if channels == 3:  # the camera frames: written out so that the loop vectorises
            for x in range(1, width):
                i, j = r + x * pixel_step, 1 + 3 * x
                out[y, j] = flat[i] - flat[i - pixel_step]
                out[y, j + 1] = flat[i + 1] - flat[i + 1 - pixel_step]
                out[y, j + 2] = flat[i + 2] - flat[i + 2 - pixel_step]
        else:
            for x in range(1, width):
                for c in range(channels):
                    i = r + x * pixel_step + c
                    out[y, 1 + x * channels + c] = flat[i] - flat[i - pixel_step]


def _bytes_of(image: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The image's memory as a flat byte array from its first byte, with its row and pixel steps; a
    view where the channels of a pixel are adjacent (the RGB of an RGBA read-back), else a copy."""
    height, width, channels = image.shape
    row_step, pixel_step, channel_step = image.strides
    if channel_step != 1 or pixel_step < channels or row_step < 0:
        image = np.ascontiguousarray(image)
        row_step, pixel_step = image.strides[:2]
    size = (height - 1) * row_step + (width - 1) * pixel_step + channels
    return np.lib.stride_tricks.as_strided(image, shape=(size,), strides=(1,), writeable=False), row_step, pixel_step


def _chunk(kind: bytes, data) -> list:
    crc = isal_zlib.crc32(data, isal_zlib.crc32(kind))
    return [struct.pack(">I", len(data)), kind, data, struct.pack(">I", crc & 0xFFFFFFFF)]


def png_bytes(image: np.ndarray, level: int = 1) -> bytes:
    """PNG file bytes of an 8-bit RGB (H, W, 3) or grey (H, W) image (any strides)."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        image = image.astype(np.uint8)
    if image.ndim == 2:
        image = image[..., None]
    height, width, channels = image.shape
    colour_type = {1: 0, 3: 2, 4: 6}[channels]
    filtered = np.empty((height, width * channels + 1), dtype=np.uint8)
    _sub_filtered(*_bytes_of(image), channels, filtered)
    header = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    parts = [SIGNATURE, *_chunk(b"IHDR", header), *_chunk(b"IDAT", isal_zlib.compress(filtered, level)),
             *_chunk(b"IEND", b"")]
    return b"".join(parts)


def png_problem(data: bytes) -> str | None:
    """What makes PNG file bytes undecodable, in words (None when sound, or not a PNG at all): truncation,
    a chunk's CRC, image data that does not inflate to the size the header gives. Checked before
    libpng sees the file; about a third of the decode's time."""
    if not data.startswith(SIGNATURE):
        return None
    view, pos, header, idat = memoryview(data), len(SIGNATURE), None, []
    while True:
        if pos + 12 > len(data):
            return f"is truncated at byte {len(data)} (no IEND chunk)"
        length, kind = struct.unpack_from(">I4s", data, pos)
        if pos + 12 + length > len(data):
            return f"is truncated at byte {len(data)}, inside its {kind.decode('latin-1')!r} chunk"
        body = view[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack_from(">I", data, pos + 8 + length)
        if isal_zlib.crc32(body, isal_zlib.crc32(kind)) & 0xFFFFFFFF != crc:
            return f"is corrupted: its {kind.decode('latin-1')!r} chunk at byte {pos} fails its CRC"
        if kind == b"IHDR" and length == 13:
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
        pos += 12 + length
    if header is None:
        return "has no image header (IHDR)"
    width, height, depth, colour, _, _, interlaced = header
    try:
        pixels = isal_zlib.decompress(b"".join(idat))
    except isal_zlib.error:
        return "is corrupted: its image data does not inflate"
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}.get(colour)
    needed = height * ((width * (channels or 0) * depth + 7) // 8 + 1)
    if not interlaced and len(pixels) != needed:
        return f"is corrupted: its image data inflates to {len(pixels)} bytes, {width} x {height} needs {needed}"
    return None


def read_frame(path: Path, check: bool = True) -> np.ndarray:
    """(H, W, 3) uint8 RGB of an 8-bit image file (a recording's frame, a run's rendered frame). check=False
    leaves out png_problem, for a file this process has read and checked before."""
    data = Path(path).read_bytes()
    problem = png_problem(data) if check else None
    if problem is not None:
        raise ArsimError(f"{path}: {problem}; give an intact 8-bit PNG file (a recording's frame: record it again)")
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) if data else None
    if image is None:
        raise ArsimError(f"{path}: cannot be read as an 8-bit image; give 8-bit PNG files (a recording's frame: "
                         "record it again)")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def read_frames(paths: Iterable[Path], workers: int = 2, ahead: int = 8, check: bool = True) -> Iterator[np.ndarray]:
    """read_frame of each path in order, decoded ahead on `workers` threads (the checks and OpenCV's decoding
    release the GIL, so they overlap the caller's work), at most `ahead` frames held at once."""
    from concurrent.futures import ThreadPoolExecutor

    pending = collections.deque()
    with ThreadPoolExecutor(workers) as pool:
        for path in paths:
            pending.append(pool.submit(read_frame, path, check))
            if len(pending) > ahead:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
