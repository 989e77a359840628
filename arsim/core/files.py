"""Atomic file writing: a file appears under its final name complete or not at all; strict JSON text."""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from arsim.core.errors import ArsimError

# mkstemp creates files readable by the owner only; finished files get the usual umask permissions.
_UMASK = os.umask(0)
os.umask(_UMASK)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path` (same suffix, so writers pick the format by it);
    on success it is renamed to `path`, on failure it is removed and `path` is left untouched."""
    path = Path(path)
    if not path.parent.exists():
        raise ArsimError(f"{path}: folder {path.parent} does not exist; create it first")
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    os.chmod(tmp, 0o666 & ~_UMASK)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def is_temporary(path: Path) -> bool:
    """A file atomic_path left behind (the writer was killed before its rename): .<stem>.<random>.tmp<suffix>."""
    return path.name.startswith(".") and ".tmp" in path.name


def clear_files(folder: Path, pattern: str) -> None:
    """Remove a folder's files matching pattern, and the temporary files a killed writer left: what is
    written there next replaces them all (no mix of an old and a new run)."""
    if folder.is_dir():
        for path in folder.iterdir():
            if path.is_file() and (path.match(pattern) or is_temporary(path)):
                path.unlink()


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write bytes to `path` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write UTF-8 text to `path` atomically."""
    write_bytes_atomic(path, text.encode("utf-8"))


def _strict(value):
    """value with every float that is not finite as None, and NumPy scalars as Python numbers."""
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        return _strict(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def json_text(value, indent: int | None = 2) -> str:
    """Strict JSON (RFC 8259) of value, a newline at the end: a figure that is not finite (a percentile
    that is infinite, a mean over no frames) is null, as JSON has no NaN or Infinity."""
    return json.dumps(_strict(value), indent=indent, allow_nan=False) + "\n"
