"""Recordings in the layouts the field uses (README: Recordings in standard layouts): EuRoC / ASL folders,
TUM-VI's additions to them (exposure times, photometric calibration) and ROS 2 bags, written from a recording
and read back as one. open_recording recognises each from its contents; load_recording hands them here."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from arsim.core.errors import ArsimError
from arsim.sensors.formats.common import Photometric
from arsim.sensors.recording import Recording, load_recording

FORMATS = ("euroc", "tumvi", "rosbag2")


def detect_format(path: Path) -> str | None:
    """'arsim', 'euroc', 'tumvi' or 'rosbag2' from what the folder holds (a bag's .mcap or .db3 file names its
    folder); None for anything else."""
    path = Path(path)
    if path.is_file() and path.suffix in (".mcap", ".db3") and (path.parent / "metadata.yaml").is_file():
        return "rosbag2"
    if not path.is_dir():
        return None
    if (path / "meta.json").is_file():
        return "arsim"
    if (path / "metadata.yaml").is_file():
        return "rosbag2"
    if (path / "mav0" / "cam0" / "data.csv").is_file():
        return "tumvi" if (path / "dso" / "cam0").is_dir() else "euroc"
    return None


def open_recording(path: Path) -> Recording:
    """The recording at path, whichever layout it is in; one ArsimError when it is none."""
    path = Path(path)
    kind = detect_format(path)
    if kind == "arsim":
        return load_recording(path)
    if kind == "euroc":
        from arsim.sensors.formats.euroc import read_euroc

        return read_euroc(path)
    if kind == "tumvi":
        from arsim.sensors.formats.tumvi import read_tumvi

        return read_tumvi(path)
    if kind == "rosbag2":
        from arsim.sensors.formats.rosbag2 import read_bag

        return read_bag(path.parent if path.is_file() else path)
    raise ArsimError(f"{path}: not a recording: neither arsim's (meta.json), EuRoC's or TUM-VI's (mav0/cam0/data.csv) "
                     "nor a ROS 2 bag (metadata.yaml)")


def ar_source(path: Path, rec: Recording) -> Path | None:
    """Where a recording's AR path lies (its meta's ar_recording, beside the layout's own files), if it has one."""
    path = Path(path)
    base = path.parent if path.is_file() else path
    sub = rec.meta.get("ar_recording")
    return base / sub if isinstance(sub, str) and detect_format(base / sub) is not None else None


def write_recording(rec: Recording, kind: str, out: Path, photometric: Photometric | None = None) -> None:
    """rec in a layout into out. photometric: the camera's calibration for TUM-VI (the recording's own where
    it carries one)."""
    if kind == "euroc":
        from arsim.sensors.formats.euroc import write_euroc

        write_euroc(rec, out)
    elif kind == "tumvi":
        from arsim.sensors.formats.tumvi import write_tumvi

        write_tumvi(rec, out, rec.photometric or photometric)
    elif kind == "rosbag2":
        from arsim.sensors.formats.rosbag2 import write_bag

        write_bag(rec, out)
    else:
        raise ArsimError(f"format {kind!r} is not known; give one of {', '.join(FORMATS)}")


def export_recording(rec: Recording, source: Path, kind: str, out: Path,
                     photometric: Callable[[Recording], Photometric | None] = lambda rec: None) -> list[tuple[Recording, Path]]:
    """A recording (open_recording(source)) and its AR path written in `kind` into out and out/ar; photometric
    gives a recording's calibration where TUM-VI needs one. Returns what was written where."""
    ar = ar_source(source, rec)
    written = []
    for r, where in ((rec, Path(out)), *(((open_recording(ar), Path(out) / "ar"),) if ar is not None else ())):
        write_recording(r, kind, where, photometric(r) if kind == "tumvi" and r.photometric is None else None)
        written.append((r, where))
    return written
