"""Fast lossless PNG writing for camera frames, and their reading.

A 640 x 480 noisy frame takes 11-23 ms through libpng (OpenCV, imagecodecs) on this class of CPU,
which alone would use a third of a recording's time budget. The PNG container is four chunks, so
arsim writes it itself and lets ISA-L (isal) do the deflate, at about 4 ms per frame and within a few
percent of libpng's size. Every row uses the Sub filter, which suits noisy photographs; a compiled
loop applies it straight from a strided view (such as the RGB of an RGBA read-back), as a copy to
contiguous RGB alone would cost half as much as the deflate. Files are checked here first (their chunks
and image data: libpng prints its own lines on standard error for a corrupted file, which would break a
refusal's one line); a frame laid out as arsim writes it is then unfiltered here from the data the check
inflated (half the time of a second inflate and unfilter by libpng), any other file read by OpenCV (the
two pixel for pixel the same in the tests).
"""

from __future__ import annotations

import collections
import contextlib
import hashlib
import os
import struct
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

import cv2
import numba
import numpy as np
from isal import isal_zlib

from arsim.core.errors import ArsimError
from arsim.core.files import atomic_path, write_text_atomic

# FFmpeg's own messages (through OpenCV) off: a damaged video is refused in arsim's one line, not FFmpeg's many.
# (Read by OpenCV when it first opens a video.)
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

SIGNATURE = b"\x89PNG\r\n\x1a\n"
SUB_FILTER = 1


def _sub_filtered(image: np.ndarray, out: np.ndarray) -> None:
    """PNG scanlines (H, 1 + W C) of an 8-bit image (H, W, C), any strides: a filter byte, then each byte minus
    the same channel of the pixel before (modulo 256). One NumPy subtraction (0.06 ms a 640 x 480 frame,
    against 0.55 for a compiled loop over a strided view)."""
    height, width, channels = image.shape
    out[:, 0] = SUB_FILTER
    out[:, 1:1 + channels] = image[:, 0]
    np.subtract(image[:, 1:], image[:, :-1], out=out[:, 1 + channels:].reshape(height, width - 1, channels))


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
    _sub_filtered(image, filtered)
    header = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    parts = [SIGNATURE, *_chunk(b"IHDR", header), *_chunk(b"IDAT", isal_zlib.compress(filtered, level)),
             *_chunk(b"IEND", b"")]
    return b"".join(parts)


def png_problem(data: bytes) -> str | None:
    """What makes PNG file bytes undecodable, in words (None when sound, or not a PNG at all): truncation,
    a chunk's CRC, image data that does not inflate to the size the header gives. Checked before
    libpng sees the file; about a third of the decode's time."""
    return _parsed(data)[0]


@numba.njit(cache=True, nogil=True)
def _sub_unfiltered(rows: np.ndarray, out: np.ndarray) -> None:
    """_sub_filtered undone for RGB scanlines (H, 1 + 3 W) whose rows all use the Sub filter: each byte plus
    the same channel of the pixel before (modulo 256), into out (H, W, 3)."""
    height, width = out.shape[0], out.shape[1]
    for y in range(height):
        # (running sums in registers: reading the pixel before back from out waited on the store each byte)
        r, g, b = 0, 0, 0
        for x in range(width):
            j = 1 + 3 * x
            r = (r + rows[y, j]) & 0xFF
            g = (g + rows[y, j + 1]) & 0xFF
            b = (b + rows[y, j + 2]) & 0xFF
            out[y, x, 0] = r
            out[y, x, 1] = g
            out[y, x, 2] = b


def _written_here(header: tuple, pixels: bytes) -> np.ndarray | None:
    """The RGB image (H, W, 3) of a PNG laid out as png_bytes writes camera frames (8-bit RGB, not
    interlaced, every row Sub-filtered), from its inflated image data; None for any other layout (OpenCV
    reads those). Its image data is inflated once, by the check, instead of again by libpng."""
    width, height, depth, colour, _, _, interlaced = header
    if depth != 8 or colour != 2 or interlaced:
        return None
    rows = np.frombuffer(pixels, np.uint8).reshape(height, 1 + 3 * width)
    if not (rows[:, 0] == SUB_FILTER).all():
        return None
    image = np.empty((height, width, 3), np.uint8)
    _sub_unfiltered(rows, image)
    return image


def _parsed(data: bytes) -> tuple[str | None, tuple | None, bytes | None]:
    """png_problem's answer, with the header and the inflated image data of a sound PNG (None, None
    where there is a problem or the bytes are not a PNG)."""
    if not data.startswith(SIGNATURE):
        return None, None, None
    view, pos, header, idat = memoryview(data), len(SIGNATURE), None, []
    while True:
        if pos + 12 > len(data):
            return f"is truncated at byte {len(data)} (no IEND chunk)", None, None
        length, kind = struct.unpack_from(">I4s", data, pos)
        if pos + 12 + length > len(data):
            return f"is truncated at byte {len(data)}, inside its {kind.decode('latin-1')!r} chunk", None, None
        body = view[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack_from(">I", data, pos + 8 + length)
        if isal_zlib.crc32(body, isal_zlib.crc32(kind)) & 0xFFFFFFFF != crc:
            return f"is corrupted: its {kind.decode('latin-1')!r} chunk at byte {pos} fails its CRC", None, None
        if kind == b"IHDR" and length == 13:
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
        pos += 12 + length
    if header is None:
        return "has no image header (IHDR)", None, None
    width, height, depth, colour, _, _, interlaced = header
    try:
        pixels = isal_zlib.decompress(b"".join(idat))
    except isal_zlib.error:
        return "is corrupted: its image data does not inflate", None, None
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}.get(colour)
    needed = height * ((width * (channels or 0) * depth + 7) // 8 + 1)
    if not interlaced and len(pixels) != needed:
        return (f"is corrupted: its image data inflates to {len(pixels)} bytes, {width} x {height} needs {needed}",
                None, None)
    return None, header, pixels


# ---------------------------------------------------------------------------------------------------
# Frames in one lossless video (a compact recording, `arsim record --compact`): FFV1 in Matroska, each frame
# intra-coded, written through PyAV with FFmpeg's bitexact flags (the same frames give the same bytes: OpenCV's
# writer stamps a random segment id) and read through OpenCV. A frame is named VIDEO#index, index from 0.

VIDEO_SUFFIX = ".mkv"


def video_frame_name(video: str, index: int) -> str:
    """How a recording's CSV names frame `index` of the video file `video` (a path under the recording)."""
    return f"{video}#{index:06d}"


def video_frame(path: str | Path) -> tuple[Path, int] | None:
    """(the video file, the frame's index) where path names a frame in a video (video_frame_name), else None."""
    path = Path(path)
    stem, sep, index = path.name.partition("#")
    if sep and stem.endswith(VIDEO_SUFFIX) and index.isdigit():
        return path.with_name(stem), int(index)
    return None


def frame_file(path: str | Path) -> Path:
    """The file holding a frame: the video for a frame in a video, else the path itself."""
    found = video_frame(path)
    return found[0] if found is not None else Path(path)


class FrameVideo:
    """Frames (H, W, 3) uint8 RGB into a lossless FFV1 video at `path`, as a context manager: written under a
    temporary name, renamed into place when the block ends without an error, with its sha256 beside it
    (`path`.sha256, as sha256sum writes it) which every reader checks: FFV1's decoder conceals damage where a
    PNG's CRC fails. Every pixel decodes as written."""

    def __init__(self, path: Path, width: int, height: int, fps: float):
        self.path, self._size, self._rate = Path(path), (width, height), fps

    def __enter__(self) -> "FrameVideo":
        try:
            import av
        except ImportError:
            raise ArsimError("compact recordings need PyAV: pip install av") from None
        from fractions import Fraction

        self._atomic = atomic_path(self.path)
        self._tmp = self._atomic.__enter__()
        rate = Fraction(self._rate).limit_denominator(1000)
        self._container = av.open(str(self._tmp), "w", format="matroska", options={"fflags": "+bitexact"})
        self._stream = self._container.add_stream("ffv1", rate=rate, options={"flags": "+bitexact"})
        self._stream.width, self._stream.height = self._size
        self._stream.pix_fmt = "bgr0"  # (lossless RGB: FFV1's encoder takes no packed rgb24)
        self._stream.codec_context.time_base = 1 / rate
        self._frames, self._av = 0, av
        return self

    def write(self, frame: np.ndarray) -> None:
        picture = self._av.VideoFrame.from_ndarray(np.ascontiguousarray(frame[..., :3]), format="rgb24")
        picture.pts, picture.time_base = self._frames, self._stream.codec_context.time_base
        for packet in self._stream.encode(picture):
            self._container.mux(packet)
        self._frames += 1

    def __exit__(self, kind, value, traceback) -> None:
        digest = None
        try:
            if kind is None:
                for packet in self._stream.encode():
                    self._container.mux(packet)
            self._container.close()
            if kind is None:
                digest = _sha256(self._tmp)
        finally:
            self._atomic.__exit__(kind, value, traceback)  # (renamed into place, or removed)
        if digest is not None:
            write_text_atomic(checksum_file(self.path), f"{digest}  {self.path.name}\n")


def checksum_file(video: Path) -> Path:
    return video.with_name(video.name + ".sha256")


def _sha256(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


_checked: dict[tuple, None] = {}  # videos (path, size, time) whose sha256 matched, in this process
_checked_lock = threading.Lock()


def _check_video(video: Path) -> None:
    """A frame video against the sha256 written beside it, once per process (and again where it changed)."""
    stat = video.stat()
    tag = (str(video.resolve()), stat.st_size, stat.st_mtime_ns)
    with _checked_lock:
        if tag in _checked:
            return
    sums = checksum_file(video)
    try:
        expected = sums.read_text(encoding="utf-8").split()[0]
    except (OSError, UnicodeDecodeError, IndexError):
        raise ArsimError(f"{video}: its checksum {sums.name} is missing or unreadable; record again") from None
    if _sha256(video) != expected:
        raise ArsimError(f"{video}: is damaged (its sha256 is not the one {sums.name} gives); record again")
    with _checked_lock:
        _checked[tag] = None


def video_size(path: Path) -> tuple[int, int, int]:
    """(width, height, frames) of a frame video; ArsimError where it cannot be opened."""
    capture = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    if not capture.isOpened():
        raise ArsimError(f"{path}: cannot be opened as a video; record again")
    try:
        return (int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)),
                int(capture.get(cv2.CAP_PROP_FRAME_COUNT)))
    finally:
        capture.release()


class _OpenVideos(threading.local):
    """Per thread, each video opened once and the index of the frame it reads next (reading in order never seeks)."""

    def __init__(self):
        self.videos: dict[Path, list] = {}


_open_videos = _OpenVideos()


def _read_video_frame(video: Path, index: int, alpha: bool = False) -> np.ndarray:
    entry = _open_videos.videos.get(video)
    if entry is None:
        if not video.is_file():
            raise ArsimError(f"{video}: missing (a compact recording's frames); record again")
        _check_video(video)
        capture = cv2.VideoCapture(str(video), cv2.CAP_FFMPEG)
        if not capture.isOpened():
            raise ArsimError(f"{video}: cannot be opened as a video; record again")
        entry = _open_videos.videos[video] = [capture, 0]
    capture, following = entry
    if index != following:
        capture.set(cv2.CAP_PROP_POS_FRAMES, index)  # (FFV1 frames are all key frames: exact)
    ok, image = capture.read()
    if not ok:
        entry[1] = -1
        raise ArsimError(f"{video}: frame {index} cannot be decoded; record again")
    entry[1] = index + 1
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGBA if alpha else cv2.COLOR_BGR2RGB)


def png_of_frame(path: Path) -> bytes:
    """A frame as PNG file bytes: a PNG's own, a video's frame encoded as a recording writes it (png_bytes)."""
    found = video_frame(path)
    return Path(path).read_bytes() if found is None else png_bytes(_read_video_frame(*found))


class _KeptFrames:
    """Frames this process wrote as PNG (write_frame_png), held decoded while kept_frames is active: the stages
    after a recording read them from memory instead of inflating them again. A frame is given back only while
    its file is the one written (the same inode, size and modification time): a file replaced, changed or
    removed since is read from disk like any other. The arrays are read-only: every reader shares one."""

    def __init__(self):
        self.lock = threading.Lock()
        self.limit = 0  # bytes; 0: not keeping
        self.held = 0
        self.frames: dict[str, tuple[tuple, np.ndarray]] = {}

    @staticmethod
    def _stamp(path: Path) -> tuple | None:
        try:
            st = os.stat(path)
        except OSError:
            return None
        return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns

    def put(self, path: Path, frame: np.ndarray) -> None:
        if not self.limit or self.held + frame.nbytes > self.limit:
            return
        stamp = self._stamp(path)
        if stamp is None:
            return
        image = np.ascontiguousarray(frame)
        image = image.copy() if image is frame else image  # (the caller's array stays the caller's)
        image.setflags(write=False)
        with self.lock:
            if self.limit and self.held + image.nbytes <= self.limit:
                old = self.frames.pop(os.path.abspath(path), None)
                self.held += image.nbytes - (old[1].nbytes if old is not None else 0)
                self.frames[os.path.abspath(path)] = (stamp, image)

    def get(self, path: Path) -> np.ndarray | None:
        if not self.frames:
            return None
        with self.lock:
            found = self.frames.get(os.path.abspath(path))
        return found[1] if found is not None and found[0] == self._stamp(path) else None


_KEPT = _KeptFrames()


@contextlib.contextmanager
def kept_frames(limit_bytes: int) -> Iterator[None]:
    """While active, the frames write_frame_png writes (up to limit_bytes of them, decoded) are what read_frame
    gives for their files; released at the end. (A run keeps its recording's frames for its capture, estimates
    and session: each would otherwise inflate every one of them again.)"""
    with _KEPT.lock:
        outer = _KEPT.limit
        _KEPT.limit = outer or int(limit_bytes)
    try:
        yield
    finally:
        if not outer:
            with _KEPT.lock:
                _KEPT.limit, _KEPT.held, _KEPT.frames = 0, 0, {}


def write_frame_png(path: Path, frame: np.ndarray) -> None:
    """A camera frame (H, W, 3) uint8 written atomically as png_bytes has it (and kept: kept_frames)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(png_bytes(frame))
    _KEPT.put(path, frame)


def read_frame(path: Path, check: bool = True, alpha: bool = False) -> np.ndarray:
    """(H, W, 3) uint8 RGB of an 8-bit image file (a recording's frame, a run's rendered frame), or of a frame in
    a video (video_frame_name). check=False leaves out png_problem, for a file this process has read and checked
    before. alpha: (H, W, 4) RGBA with alpha 255 instead, the layout the renderer uploads as it is (the one
    conversion a decoded frame needs anyway, made here, on the thread that decodes)."""
    kept = _KEPT.get(path)
    if kept is not None:
        return _with_alpha(kept) if alpha else kept
    found = video_frame(path)
    if found is not None:
        return _read_video_frame(*found, alpha)
    data = Path(path).read_bytes()
    problem, header, pixels = _parsed(data) if check else (None, None, None)
    if problem is not None:
        raise ArsimError(f"{path}: {problem}; give an intact 8-bit PNG file (a recording's frame: record it again)")
    if header is not None and (image := _written_here(header, pixels)) is not None:
        return _with_alpha(image) if alpha else image
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) if data else None
    if image is None:
        raise ArsimError(f"{path}: cannot be read as an 8-bit image; give 8-bit PNG files (a recording's frame: "
                         "record it again)")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGBA if alpha else cv2.COLOR_BGR2RGB)


def _with_alpha(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2RGBA)


def read_frames(paths: Iterable[Path], workers: int = 2, ahead: int = 8, check: bool = True,
                alpha: bool = False) -> Iterator[np.ndarray]:
    """read_frame of each path in order (alpha: as read_frame's), decoded ahead on `workers` threads (the checks
    and OpenCV's decoding release the GIL, so they overlap the caller's work), at most `ahead` frames held at once."""
    from concurrent.futures import ThreadPoolExecutor

    paths = list(paths)
    if paths and video_frame(paths[0]) is not None:
        workers = 1  # (a video is decoded in order, by one thread: no seeking)
    pending = collections.deque()
    with ThreadPoolExecutor(workers) as pool:
        for path in paths:
            pending.append(pool.submit(read_frame, path, check, alpha))
            if len(pending) > ahead:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
