"""TUM-VI's additions to the EuRoC layout (README: Recordings in standard layouts): what a direct method needs
of the camera, in the dso/ folder TUM-VI's sequences ship beside mav0/:

  dso/cam0/times.txt      one line per frame: timestamp [ns], timestamp [s], exposure time [ms] (DSO's times.txt)
  dso/cam0/pcalib.txt     the inverse response: 256 values on one line, each 8-bit code's irradiance (0-255)
  dso/cam0/vignette.png   the vignette, 16-bit grey, 65535 where the lens passes the most
  dso/cam0/camera.txt     DSO's camera file (RadTan fx fy cx cy k1 k2 0 0; the size; no rectification)
  mav0/mocap0/data.csv    the ground truth: timestamp [ns], position, quaternion w, x, y, z

vignette.png's 16 bits quantise the vignette to 1.5e-5 relative in the darkest corners; arsim/vignette.exr keeps
it as float32 for an exact round trip (a TUM-VI reader ignores it; arsim reads it in place of the PNG).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from arsim.core.errors import ArsimError
from arsim.core.files import atomic_path, write_text_atomic
from arsim.core.hdr_io import read_hdr, write_exr
from arsim.core.png import png_problem
from arsim.sensors.formats.common import Photometric
from arsim.sensors.formats.euroc import EXTRAS, read_euroc, write_euroc, yaml_float
from arsim.sensors.recording import Recording

DSO = "dso/cam0"


def write_tumvi(rec: Recording, out: Path, photometric: Photometric | None) -> None:
    """rec in TUM-VI's layout; photometric: the camera's calibration (the recording's own where it has one)."""
    write_euroc(rec, out, groundtruth_folder="mocap0")
    dso = out / DSO
    dso.mkdir(parents=True, exist_ok=True)
    write_text_atomic(dso / "times.txt", "# timestamp [ns] timestamp [s] exposure [ms]\n" + "".join(
        f"{f['t_ns']} {f['t_ns'] // 1_000_000_000}.{f['t_ns'] % 1_000_000_000:09d} {f['exposure_ns'] // 1_000_000}."
        f"{f['exposure_ns'] % 1_000_000:06d}\n" for f in rec.frames))
    cam = rec.meta["camera"]
    write_text_atomic(dso / "camera.txt", f"RadTan {' '.join(yaml_float(cam[k]) for k in ('fx', 'fy', 'cx', 'cy', 'k1', 'k2'))} 0 0\n"
                      f"{cam['width']} {cam['height']}\nnone\n{cam['width']} {cam['height']}\n")
    if photometric is None:
        return
    write_text_atomic(dso / "pcalib.txt", " ".join(repr(float(v)) for v in photometric.inverse_response) + "\n")
    vignette = np.asarray(photometric.vignette, dtype=np.float32)
    with atomic_path(dso / "vignette.png") as tmp:
        cv2.imwrite(str(tmp), np.round(np.clip(vignette, 0.0, 1.0) * 65535.0).astype(np.uint16),
                    [cv2.IMWRITE_PNG_COMPRESSION, 9])
    write_exr(out / EXTRAS / "vignette.exr", np.repeat(vignette[..., None], 3, axis=-1))


def _times(path: Path) -> dict[int, int] | None:
    """times.txt: {t_ns: exposure_ns}."""
    if not path.is_file():
        return None
    out, previous = {}, None
    for k, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        fields = line.replace(",", " ").split()
        if not fields or fields[0].startswith("#"):
            continue
        try:
            t, exposure_ms = int(fields[0]), float(fields[2])
        except (ValueError, IndexError, OverflowError):
            raise ArsimError(f"{path}: line {k} is not 'timestamp [ns] timestamp [s] exposure [ms]'") from None
        if not 0 < exposure_ms < 1e7:
            raise ArsimError(f"{path}: line {k}: exposure {exposure_ms} ms is not a positive time")
        if previous is not None and t <= previous:
            raise ArsimError(f"{path}: line {k}: timestamp {t} ns is not after the previous line's {previous} ns; "
                             "the lines must be in increasing time order")
        out[t], previous = int(round(exposure_ms * 1e6)), t
    return out


def _photometric(root: Path) -> Photometric | None:
    dso = root / DSO
    pcalib, png = dso / "pcalib.txt", dso / "vignette.png"
    if not pcalib.is_file() and not png.is_file():
        return None
    if not pcalib.is_file() or not png.is_file():
        raise ArsimError(f"{dso}: has {'pcalib.txt' if pcalib.is_file() else 'vignette.png'} without "
                         f"{'vignette.png' if pcalib.is_file() else 'pcalib.txt'}; the photometric calibration needs both")
    try:
        inverse = np.array([float(v) for v in pcalib.read_text(encoding="utf-8").split()])
    except (ValueError, UnicodeDecodeError):
        raise ArsimError(f"{pcalib}: holds something that is not a number; give 256 numbers") from None
    if inverse.shape != (256,):
        raise ArsimError(f"{pcalib}: holds {inverse.size} values; the inverse response is 256 (one per 8-bit code)")
    exact = root / EXTRAS / "vignette.exr"
    if exact.is_file():
        vignette = read_hdr(exact)[..., 0].astype(np.float32)
    else:
        data = png.read_bytes()
        problem = png_problem(data)
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data and not problem else None
        if image is None or image.ndim != 2:
            raise ArsimError(f"{png}: {problem or 'is not a grey PNG image'}; give the vignette as a 16-bit grey PNG")
        vignette = (image.astype(np.float64) / max(float(image.max()), 1.0)).astype(np.float32)  # (as DSO reads it)
    return Photometric(inverse, vignette)


def read_tumvi(root: Path) -> Recording:
    root = Path(root)
    return read_euroc(root, _times(root / DSO / "times.txt"), _photometric(root), "tumvi")
