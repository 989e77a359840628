"""The run cache (README: The run cache): each stage of `arsim run` keyed by a hash of exactly what it depends
on (the settings it reads, the keys of the stages it takes from, arsim's version and the source of the code it
runs); its outputs kept in a cache folder and reused, verified, when the key matches.

An entry is a folder CACHE/<stage>/<key>/ holding files/ (the stage's outputs, as they lie in the run
directory), state/ (what a later stage needs in memory and cannot read back from the outputs: .npz arrays
and .json) and entry.json (every file of files/ and state/ with its sha256 and size). An entry is written
into CACHE/tmp/ and renamed into place whole; on reuse every file is checked against entry.json, and an
entry that fails (a file missing, changed or added) is removed and the stage computed again, never partly
used. A stage is computed under a lock on its key, so runs at once (`arsim batch --workers N`) that share a
stage compute it once.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import re
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from arsim import __version__
from arsim.core.errors import ArsimError
from arsim.core.files import platform_cache_dir, user_cache_dir

MAX_BYTES_VAR = "ARSIM_CACHE_MAX_GB"
DEFAULT_MAX_GB = 20.0  # the least recently used entries go beyond it
ENTRY = "entry.json"
KEY_CHARS = 32  # of the sha256's hex digits: a folder name

PACKAGE = Path(__file__).resolve().parents[1]  # arsim/


def default_cache_dir() -> Path:
    """$ARSIM_CACHE; else (also where it is off) the user's cache folder (core.files.platform_cache_dir)."""
    return user_cache_dir() or platform_cache_dir()


def cache_folder(given: Path | None, disabled: bool) -> Path | None:
    """The cache a run uses: --cache DIR, else the default; None with --no-cache or ARSIM_CACHE=off."""
    if disabled:
        return None
    return given if given is not None else user_cache_dir()


# ---------------------------------------------------------------------------------------------------
# Keys


def sha256_file(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


_file_hashes: dict[tuple, str] = {}


def sha256_files(paths) -> list[str]:
    """The files' sha256 in their order, hashed on as many threads as there are cores (hashlib lets go of the GIL:
    a recording's gigabyte hashes in about half the time on two)."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(os.cpu_count() or 1) as pool:
        return list(pool.map(sha256_file, paths))


def _hashes_match(expected: dict[Path, str]) -> bool:
    """Whether every file has its sha256."""
    return all(h == expected[p] for p, h in zip(expected, sha256_files(expected)))


def settings_digest(value):
    """A section (dataclass), tuple or value as JSON-able data; a path naming a file becomes its name and
    the sha256 of its content (an environment map or mesh edited in place changes the key)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: settings_digest(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): settings_digest(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [settings_digest(v) for v in value]
    if isinstance(value, Path) or (isinstance(value, str) and os.sep in value):
        path = Path(value)
        if path.is_file():
            stat = path.stat()
            tag = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
            if tag not in _file_hashes:
                _file_hashes[tag] = sha256_file(path)
            return {"file": path.name, "sha256": _file_hashes[tag]}
        return str(value)
    if isinstance(value, float) and not np.isfinite(value):
        return repr(value)
    return value


def key_of(stage: str, parts: dict) -> str:
    """The stage's key: the sha256 of its parts (settings, the keys it takes from, code), with arsim's and
    the numeric libraries' versions."""
    import cv2

    text = json.dumps({"stage": stage, "arsim": __version__, "numpy": np.__version__, "opencv": cv2.__version__,
                       **parts}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:KEY_CHARS]


def _module_file(name: str) -> Path | None:
    parts = name.split(".")[1:]
    if not parts:
        return PACKAGE / "__init__.py"
    rel = Path(*parts)
    for candidate in (PACKAGE / rel.with_suffix(".py"), PACKAGE / rel / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+(arsim[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n]*)|import[ \t]+(arsim[\w.]*))", re.M)
_imports_of: dict[tuple, frozenset] = {}


def _imports(path: Path) -> frozenset[str]:
    """The arsim modules a source file imports, anywhere in it (functions' imports too); `from package
    import name` counts the module package.name where there is one, else the whole package (a package's
    names may be lazy: any of its modules)."""
    stat = path.stat()
    tag = (str(path), stat.st_size, stat.st_mtime_ns)
    if tag in _imports_of:
        return _imports_of[tag]
    found = set()
    for module, names, plain in _IMPORT.findall(path.read_text(encoding="utf-8")):
        if plain:
            found.add(plain)
            continue
        for name in re.split(r"[\s,()]+", names.split("#")[0] if not names.startswith("(") else names):
            name = name.strip()
            if not name or name == "as" or not name.isidentifier():
                continue
            sub = f"{module}.{name}"
            if _module_file(sub) is not None:
                found.add(sub)
            else:
                found.add(module)
                file = _module_file(module)
                if file is not None and file.name == "__init__.py" and module != "arsim":  # (arsim's: the version)
                    found |= {f"{module}.{p.stem}" for p in file.parent.glob("*.py") if p.stem != "__init__"}
    _imports_of[tag] = frozenset(found)
    return _imports_of[tag]


def code_files(modules: tuple[str, ...], files: tuple[str, ...] = ()) -> list[str]:
    """The source files (paths under arsim/) of the modules a stage runs: the entry modules and every arsim
    module they import, transitively (module by module), arsim/__init__.py (the version); plus files, taken
    without following their imports (the modules that orchestrate the stages: the parts a stage runs are
    among its entry modules)."""
    seen: dict[str, Path] = {}
    todo = list(modules)
    while todo:
        name = todo.pop()
        file = _module_file(name)
        if name in seen or file is None:
            continue
        seen[name] = file
        todo += sorted(_imports(file) - set(seen))
    return sorted({p.relative_to(PACKAGE).as_posix() for p in seen.values()} | set(files) | {"__init__.py"})


def code_digest(modules: tuple[str, ...], files: tuple[str, ...] = ()) -> str:
    """The sha256 of code_files' source."""
    h = hashlib.sha256()
    for rel in code_files(modules, files):
        h.update(rel.encode() + b"\0" + (PACKAGE / rel).read_bytes() + b"\0")
    return h.hexdigest()


# ---------------------------------------------------------------------------------------------------
# State: what a later stage needs in memory, as .npz arrays (no pickles) and lossless JSON


def _encode(value):
    """JSON-able, lossless for what the stages hold: NaN and infinities kept (Python's JSON reads them
    back), tuples as lists, dicts with keys that are not strings as tagged item lists, arrays as lists."""
    if isinstance(value, dict):
        if all(isinstance(k, str) for k in value):
            return {k: _encode(v) for k, v in value.items()}
        return {"__items__": [[_encode(k), _encode(v)] for k, v in value.items()]}
    if isinstance(value, (list, tuple)):
        return [_encode(v) for v in value]
    if isinstance(value, np.ndarray):
        return _encode(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


def _decode(value):
    if isinstance(value, dict):
        if set(value) == {"__items__"}:
            return {_decode(k): _decode(v) for k, v in value["__items__"]}
        return {k: _decode(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_decode(v) for v in value]
    return value


def write_state(folder: Path, data: dict | None = None, arrays: dict[str, np.ndarray] | None = None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    if data is not None:
        (folder / "state.json").write_text(json.dumps(_encode(data), indent=1), encoding="utf-8")
    if arrays is not None:
        np.savez(folder / "arrays.npz", **arrays)


def read_state(folder: Path) -> tuple[dict, dict[str, np.ndarray]]:
    data = json.loads((folder / "state.json").read_text(encoding="utf-8")) if (folder / "state.json").is_file() else {}
    arrays = {}
    if (folder / "arrays.npz").is_file():
        with np.load(folder / "arrays.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    return _decode(data), arrays


# ---------------------------------------------------------------------------------------------------
# Entries


def _link_or_copy(source: Path, target: Path) -> None:
    """A hard link where both lie on one file system (no copy of a recording's gigabyte), else a copy. Every
    writer of arsim replaces a file (core/files.py) rather than writing into it, so a link is never changed
    through the run; one changed anyway fails the entry's hashes and the stage is computed again."""
    target.unlink(missing_ok=True)
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def _files(root: Path) -> list[str]:
    return list(snapshot(root))


def snapshot(out: Path) -> dict[str, tuple[int, int]]:
    """The files of a run directory (their paths under it, sorted) with size and time: what a stage wrote is what
    differs after it. One stat a file from the directory walk itself (Path.rglob and two stats a file took 0.9 s
    of a default run, whose recording holds 2,400 files, over its twelve snapshots)."""
    found: dict[str, tuple[int, int]] = {}

    def walk(folder: str, prefix: str) -> None:
        with os.scandir(folder) as entries:
            for entry in entries:
                if entry.is_dir(follow_symlinks=False):
                    walk(entry.path, prefix + entry.name + "/")
                elif entry.is_file():  # (a link to a file counts, with its target's size and time, as before)
                    stat = entry.stat()
                    found[prefix + entry.name] = (stat.st_size, stat.st_mtime_ns)

    walk(os.fspath(out), "")
    return dict(sorted(found.items()))


@dataclasses.dataclass(frozen=True)
class Hit:
    folder: Path  # the entry
    hashes: dict[str, str]  # files/<path in the run> -> sha256, as verified

    @property
    def outputs(self) -> dict[str, str]:
        """The run's paths of the stage's outputs -> sha256."""
        return {k.removeprefix("files/"): v for k, v in self.hashes.items() if k.startswith("files/")}

    @property
    def state(self) -> Path:
        return self.folder / "state"


class StageCache:
    """The cache folder; every method a no-op where root is None (--no-cache)."""

    def __init__(self, root: Path | None, max_bytes: float | None = None):
        self.root = root
        if max_bytes is None:
            text = os.environ.get(MAX_BYTES_VAR, "").strip() or str(DEFAULT_MAX_GB)
            try:
                max_bytes = float(text) * 2**30
            except ValueError:
                max_bytes = float("nan")
            if not max_bytes >= 0:
                raise ArsimError(f"${MAX_BYTES_VAR} = {text!r}: not a size in GiB; give a number such as 20")
        self.max_bytes = max_bytes
        if root is not None:
            try:
                (root / "tmp").mkdir(parents=True, exist_ok=True)
                (root / "locks").mkdir(exist_ok=True)
            except OSError as exc:
                raise ArsimError(f"{root}: cannot use it as the run cache ({exc.strerror or exc}); give another folder "
                                 "with --cache DIR, or --no-cache") from None

    def entry(self, stage: str, key: str) -> Path | None:
        return None if self.root is None else self.root / stage / key

    @contextlib.contextmanager
    def lock(self, stage: str, key: str) -> Iterator[None]:
        """Held while the stage is looked up, computed and stored: a run at once with the same key waits, then
        reuses the entry."""
        if self.root is None:
            yield
            return
        try:
            import fcntl
        except ImportError:  # (no file locks here: both compute, the first rename wins)
            yield
            return
        with open(self.root / "locks" / f"{stage}-{key}.lock", "w") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(handle, fcntl.LOCK_UN)

    def lookup(self, stage: str, key: str) -> Hit | None:
        """The entry, verified file by file against entry.json; one that fails is removed (None)."""
        folder = self.entry(stage, key)
        if folder is None or not folder.is_dir():
            return None
        try:
            listed = json.loads((folder / ENTRY).read_text(encoding="utf-8"))["files"]
            present = [p for p in _files(folder) if p != ENTRY]
            ok = sorted(listed) == present and all(
                (folder / rel).stat().st_size == f["bytes"] for rel, f in listed.items()) and _hashes_match(
                {folder / rel: f["sha256"] for rel, f in listed.items()})
        except (OSError, ValueError, KeyError, TypeError):
            ok = False
        if not ok:
            shutil.rmtree(folder, ignore_errors=True)
            return None
        os.utime(folder / ENTRY)  # (recently used: pruned last)
        return Hit(folder, {rel: f["sha256"] for rel, f in listed.items()})

    def restore(self, hit: Hit, out: Path, borrowed=lambda rel: False) -> None:
        """The entry's outputs linked (or copied) into the run directory. Those borrowed(path) holds for are read
        while the run works and left out of it at its end (a recording's frames): never copied, a symbolic link
        into the entry where a hard link cannot be made (another file system)."""
        for rel in hit.outputs:
            target = out / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            if borrowed(rel):
                target.unlink(missing_ok=True)
                try:
                    os.link(hit.folder / "files" / rel, target)
                except OSError:
                    os.symlink(hit.folder / "files" / rel, target)
            else:
                _link_or_copy(hit.folder / "files" / rel, target)

    def store(self, stage: str, key: str, out: Path, outputs: list[str], state=None) -> Path | None:
        """A new entry: the outputs (paths in out) copied, state(folder) writing what later stages need; written
        in CACHE/tmp and renamed into place. Returns the entry (None without a cache)."""
        folder = self.entry(stage, key)
        if folder is None:
            return None
        tmp = Path(tempfile.mkdtemp(prefix=f"{stage}-{key}.", dir=self.root / "tmp"))
        try:
            for rel in outputs:
                target = tmp / "files" / rel
                target.parent.mkdir(parents=True, exist_ok=True)
                _link_or_copy(out / rel, target)
            if state is not None:
                state(tmp / "state")
            rels = _files(tmp)
            files = {rel: {"sha256": h, "bytes": (tmp / rel).stat().st_size}
                     for rel, h in zip(rels, sha256_files([tmp / rel for rel in rels]))}
            (tmp / ENTRY).write_text(json.dumps({"stage": stage, "key": key, "arsim": __version__, "created": time.time(),
                                                 "files": files}, indent=1), encoding="utf-8")
            folder.parent.mkdir(exist_ok=True)
            if folder.exists():  # (an entry that failed verification was removed; one stored meanwhile is as good)
                shutil.rmtree(tmp)
                return folder
            os.rename(tmp, folder)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        self.prune()
        return folder

    def entries(self) -> list[tuple[str, Path, int, float]]:
        """(stage, folder, bytes, last used) of every entry."""
        found = []
        if self.root is None or not self.root.is_dir():
            return found
        for entry in sorted(self.root.glob(f"*/*/{ENTRY}")):
            if entry.parent.parent.name in ("tmp", "locks"):
                continue
            try:
                files = json.loads(entry.read_text(encoding="utf-8"))["files"]
                size = sum(f["bytes"] for f in files.values())
            except (OSError, ValueError, KeyError, TypeError):
                size = 0
            found.append((entry.parent.parent.name, entry.parent, size, entry.stat().st_mtime))
        return found

    def prune(self) -> None:
        """The least recently used entries removed until the cache holds at most max_bytes."""
        entries = sorted(self.entries(), key=lambda e: e[3])
        total = sum(e[2] for e in entries)
        for _, folder, size, _ in entries:
            if total <= self.max_bytes:
                break
            shutil.rmtree(folder, ignore_errors=True)
            total -= size

    def info(self) -> dict:
        per_stage: dict[str, dict] = {}
        for stage, _, size, _ in self.entries():
            s = per_stage.setdefault(stage, {"entries": 0, "bytes": 0})
            s["entries"] += 1
            s["bytes"] += size
        return {"folder": str(self.root), "entries": sum(s["entries"] for s in per_stage.values()),
                "bytes": sum(s["bytes"] for s in per_stage.values()), "max_bytes": int(self.max_bytes),
                "stages": per_stage}

    def clear(self) -> int:
        """Every entry removed; returns how many."""
        entries = self.entries()
        for _, folder, _, _ in entries:
            shutil.rmtree(folder, ignore_errors=True)
        if self.root is not None:
            for leftover in (self.root / "tmp").glob("*"):
                shutil.rmtree(leftover, ignore_errors=True)
            for lock in (self.root / "locks").glob("*.lock"):  # (one held now: that run's entry is still stored whole)
                lock.unlink(missing_ok=True)
        return len(entries)
