"""Atomic writing: a file appears under its final name complete or not at all, and so does a command's
output folder (written beside it under a temporary name, then swapped in whole); strict JSON text."""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import os
import shutil
import socket
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path

from arsim.core.errors import ArsimError

# mkdtemp creates folders for the owner only; finished output folders get the usual umask permissions.
_UMASK = os.umask(0)
os.umask(_UMASK)
_names = itertools.count()  # (atomic_path's temporary names)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path` (same suffix, so writers pick the format by it);
    on success it is renamed to `path`, on failure it is removed and `path` is left untouched."""
    path = Path(path)
    if not path.parent.exists():
        raise ArsimError(f"{path}: folder {path.parent} does not exist; create it first")
    # A name no other writer uses at the same time (this process, this thread, a count), the file left for the
    # writer to create with the usual permissions: mkstemp's file, closed and its mode set, took half the time
    # of writing a recording's frame.
    tmp = path.with_name(f".{path.stem}.{os.getpid()}-{threading.get_ident()}-{next(_names)}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


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


def _as_list(value):
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def json_text(value, indent: int | None = 2) -> str:
    """Strict JSON (RFC 8259) of value, a newline at the end: a figure that is not finite (a percentile
    that is infinite, a mean over no frames) is null, as JSON has no NaN or Infinity."""
    try:  # (most values hold only finite numbers: encoded at once, NumPy's as they come, not copied first)
        return json.dumps(value, indent=indent, allow_nan=False, default=_as_list) + "\n"
    except ValueError:  # (a float that is not finite)
        return json.dumps(_strict(value), indent=indent, allow_nan=False) + "\n"


# The file that marks a folder as an arsim command's output: such a folder is replaced whole by the next
# command writing there; a folder holding other files is replaced only when asked (--force).
OUTPUT_MARK = ".arsim-output"


def _owner_tag() -> str:
    """host.pid of this process, in the names of its temporary folders: a later command removes those of
    a process on this host that is no longer running (one killed before its rename)."""
    return f"{socket.gethostname()}.{os.getpid()}"


def _stale(name: str, prefix: str) -> bool:
    host, _, rest = name.removeprefix(prefix).partition(".")
    pid = rest.split(".", 1)[0]
    if host != socket.gethostname() or not pid.isdigit():
        return False  # another machine's (a shared file system): it may still be writing
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False  # running, as another user
    return False


def check_output_folder(path: Path, force: bool = False, inputs: tuple = ()) -> None:
    """ArsimError, before any work, unless `path` can take a command's output: a new folder, an empty
    one, one an arsim command wrote (replaced whole), or any folder with force; never a file, the folder
    the shell is in (or one above it), or a folder holding one of the command's inputs."""
    if path.exists() and not path.is_dir():
        raise ArsimError(f"{path}: exists and is not a folder; give a folder for -o")
    resolved = path.resolve()
    cwd = Path.cwd().resolve()
    if resolved == cwd or resolved in cwd.parents:
        raise ArsimError(f"{path}: is the folder you are in (or holds it), which the output would replace; "
                         "give a new folder for -o, e.g. -o out")
    for source in inputs:
        held = Path(source).resolve() if source is not None else None
        if held is not None and (held == resolved or resolved in held.parents):
            raise ArsimError(f"{path}: holds the input {source}, which the output would replace; give another folder for -o")
    if path.is_dir() and not force and not (path / OUTPUT_MARK).is_file() and any(path.iterdir()):
        raise ArsimError(f"{path}: holds files arsim did not write; give a new or empty folder for -o, "
                         "or pass --force to replace the folder and everything in it")


@contextlib.contextmanager
def staged_folder(path: str | os.PathLike, command: str) -> Iterator[Path]:
    """Yield a new temporary folder beside `path` to write a command's output into. On success it
    replaces `path` whole (what was there is removed, so old and new files never mix) and is marked as
    arsim's output; on failure or interruption it is removed and `path` is left as it was."""
    path = Path(path)
    target = path.resolve() if path.is_symlink() else path  # (the folder a link points to is replaced, not the link)
    parent = target.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        for kind in ("tmp", "old"):  # left by a command killed before it finished
            prefix = f".{target.name}.{kind}-"
            for leftover in parent.glob(prefix + "*"):
                if leftover.is_dir() and _stale(leftover.name, prefix):
                    shutil.rmtree(leftover, ignore_errors=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-{_owner_tag()}.", dir=parent))
    except OSError as exc:
        raise ArsimError(f"{path}: cannot write a folder in {parent} ({exc.strerror or exc}); "
                         "give a folder for -o where you can write") from None
    try:
        os.chmod(tmp, 0o777 & ~_UMASK)
        yield tmp
        (tmp / OUTPUT_MARK).write_text(f"written by arsim {command}; the next command writing here replaces this folder whole\n",
                                       encoding="utf-8")
        if target.exists():
            old = parent / f".{target.name}.old-{_owner_tag()}"
            shutil.rmtree(old, ignore_errors=True)
            os.rename(target, old)
            os.rename(tmp, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


CACHE_ENV = "ARSIM_CACHE"  # arsim's cache folder, or "off" (no cache)


def platform_cache_dir() -> Path:
    """The user's cache folder for arsim: platformdirs' where it is installed, else $XDG_CACHE_HOME/arsim
    (~/.cache/arsim)."""
    try:
        import platformdirs
    except ImportError:
        return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "arsim"
    return Path(platformdirs.user_cache_dir("arsim"))


def user_cache_dir() -> Path | None:
    """arsim's cache folder (the run cache's entries, PRT transfers): $ARSIM_CACHE, None where it says "off",
    else platform_cache_dir()."""
    given = os.environ.get(CACHE_ENV, "").strip()
    if given.lower() == "off":
        return None
    return Path(given).expanduser() if given else platform_cache_dir()
