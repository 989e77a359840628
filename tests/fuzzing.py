"""Hypothesis strategies for adversarial inputs, drawn from what arsim declares: scenarios from the
schema's sections (each key's type, range and choices, then values just outside them and values of the
wrong kind), recordings mutated file by file, and command-line options. Used by tests/test_fuzz.py
(a bounded budget) and benchmarks/fuzz.py (the long profile)."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

import tomli_w
from hypothesis import strategies as st

from arsim.scenario.sections import Scenario

JUNK = st.one_of(
    st.integers(min_value=-(10 ** 400), max_value=10 ** 400),  # 400 digits
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=40),
    st.text(alphabet=st.characters(codec="utf-8"), min_size=200, max_size=320),  # a 300-character path
    st.sampled_from(["~nosuchuser/x.exr", "a\x00b.exr", "/", ".", "..", "/dev/null", "/proc/self/mem", "envmaps",
                     "envmaps/city.exr", "meshes", "C:\\x.exr", "", " ", "nan", "inf", "-0"]),
    st.booleans(),
    st.lists(st.integers(-5, 5), max_size=4),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)


def _value(f: dataclasses.Field, tp) -> st.SearchStrategy:
    """A value for one key: in range, at or past its bounds, one of its choices, or junk."""
    meta = f.metadata
    lo, hi, choices = meta.get("min"), meta.get("max"), meta.get("choices")
    options = [JUNK, st.just(f.default)]
    if choices:
        options.append(st.sampled_from([c for c in choices]))
    base = typing.get_args(tp)[0] if typing.get_origin(tp) is tuple else tp
    if base in (int, float) or (isinstance(base, type) and issubclass(base, (int, float))):
        edges = [v for v in (lo, hi) if v is not None]
        near = [e * k for e in edges for k in (1, 0.999, 1.001, -1, 10)] + [0, -1, 1e308, -1e308]
        number = st.one_of(st.sampled_from(near), st.floats(lo if lo is not None else -1e6, hi if hi is not None else 1e6)
                           if base is float else st.integers(int(lo) if lo is not None else -10 ** 6,
                                                             int(hi) if hi is not None else 10 ** 6))
        if base is int:
            number = number.map(lambda v: int(v) if abs(v) < 1e300 else v)
        options.append(number)
        if typing.get_origin(tp) is tuple:
            n = len(typing.get_args(tp)) if typing.get_args(tp)[-1] is not Ellipsis else 3
            options.append(st.lists(number, min_size=max(0, n - 1), max_size=n + 1))
    return st.one_of(options)


def section_table(cls, depth: int = 0) -> st.SearchStrategy:
    """A TOML table for a section: some of its keys (fuzzed), sometimes an unknown one."""
    hints = typing.get_type_hints(cls)
    keys = {}
    for f in dataclasses.fields(cls):
        sub = f.metadata.get("section")
        if sub is not None:
            if depth > 2:
                continue
            inner = section_table(sub, depth + 1)
            keys[f.name] = st.lists(inner, max_size=3) if f.metadata["array"] else inner
        else:
            keys[f.name] = _value(f, hints[f.name])
    chosen = st.lists(st.sampled_from(sorted(keys)), unique=True, max_size=min(6, len(keys)))
    extra = st.dictionaries(st.sampled_from(["unknown", "sedd", "map_sise"]), JUNK, max_size=1)
    return st.tuples(chosen, extra).flatmap(
        lambda ce: st.fixed_dictionaries({k: keys[k] for k in ce[0]}).map(lambda d, e=ce[1]: d | e))


def _toml(table: dict) -> str | None:
    try:
        return tomli_w.dumps(table)
    except (TypeError, ValueError, OverflowError):
        return None  # not expressible in TOML (NaN keys, None): the raw-text strategy covers broken files


def _raw_mutation(text: str, data: st.DataObject) -> str:
    """Break a valid TOML text: cut it, duplicate a line, insert bytes."""
    kind = data.draw(st.sampled_from(["cut", "dup", "insert"]))
    k = data.draw(st.integers(0, max(0, len(text))))
    if kind == "cut":
        return text[:k]
    if kind == "dup":
        lines = text.splitlines()
        return "\n".join(lines + lines[: data.draw(st.integers(0, len(lines)))])
    return text[:k] + data.draw(st.text(max_size=12)) + text[k:]


@st.composite
def scenario_texts(draw) -> str:
    """A scenario file's text: a fuzzed table per section, as TOML, sometimes broken as text."""
    table = draw(section_table(Scenario))
    text = _toml(table) or ""
    if draw(st.integers(0, 9)) == 0:
        text = _raw_mutation(text, draw(st.data()))
    return text


RECORDING_FILES = ("meta.json", "frames.csv", "burst.csv", "imu.csv", "orientation.csv", "groundtruth.csv")


@st.composite
def recording_mutations(draw):
    """A function that damages a recording folder in one of the ways a disk, a tool or a person would."""
    target = draw(st.sampled_from(RECORDING_FILES + ("frame",)))
    kind = draw(st.sampled_from(["truncate", "empty", "bytes", "folder", "delete", "line", "json"]))
    cut = draw(st.floats(0, 1))
    junk = draw(st.binary(max_size=32))
    line_index = draw(st.integers(0, 40))
    cell = draw(st.text(max_size=12))
    json_value = draw(JUNK)
    json_key = draw(st.sampled_from(["seed", "camera", "scenario_toml", "duration_s", "camera_to_device", "format",
                                     "fusion", "table"]))

    def mutate(folder: Path) -> str:
        import json
        import shutil

        path = folder / (sorted((folder / "frames").glob("*.png"))[line_index % 10].relative_to(folder)
                         if target == "frame" else target)
        data = path.read_bytes()
        if kind == "truncate":
            path.write_bytes(data[: int(cut * len(data))])
        elif kind == "empty":
            path.write_bytes(b"")
        elif kind == "bytes":
            k = int(cut * len(data))
            path.write_bytes(data[:k] + junk + data[k:])
        elif kind == "folder":
            path.unlink()
            path.mkdir()
        elif kind == "delete":
            path.unlink()
        elif kind == "line" and path.suffix == ".csv":
            lines = data.decode("utf-8").splitlines()
            k = line_index % max(1, len(lines))
            cells = lines[k].split(",")
            cells[int(cut * (len(cells) - 1))] = cell.replace("\n", " ")
            lines[k] = ",".join(cells)
            path.write_text("\n".join(lines) + "\n", encoding="utf-8")
        elif kind == "json" and path.name == "meta.json":
            meta = json.loads(data)
            if isinstance(json_value, bool) and json_value:
                meta.pop(json_key, None)
            elif json_key == "camera" and isinstance(meta.get("camera"), dict):
                meta["camera"][sorted(meta["camera"])[line_index % len(meta["camera"])]] = json_value
            else:
                meta[json_key] = json_value
            try:
                path.write_text(json.dumps(meta), encoding="utf-8")
            except (ValueError, OverflowError):
                path.write_text("{", encoding="utf-8")
        else:
            shutil.rmtree(path) if path.is_dir() else path.write_bytes(data + junk)
        return f"{target}: {kind}"

    return mutate


OPTION_VALUES = st.one_of(st.sampled_from(["0", "-1", "1", "nan", "inf", "-inf", "1e308", "1e-308", "3", "64", "x", "",
                                           "1,2", "1,,2", ",", "5000", "1000000000", "-3", "0.5", "auto", "2,1e9"]),
                          st.text(max_size=8))

BAKE_OPTIONS = {"--spec": OPTION_VALUES, "--sh-order": OPTION_VALUES,
                "--samples": OPTION_VALUES, "--seed": OPTION_VALUES,
                "--method": st.sampled_from(["fast", "sh", "mc", "mipmap", "accurate", "bounds", "nope", ""])}


@st.composite
def bake_options(draw) -> list[str]:
    """Options of `arsim bake` (the command that takes the most numeric options), values fuzzed; the maps'
    size is left to the caller (a large one is a long job, not a bug)."""
    names = draw(st.lists(st.sampled_from(sorted(BAKE_OPTIONS)), unique=True, max_size=4))
    args = []
    for name in names:
        args.append(f"{name}={draw(BAKE_OPTIONS[name])}")
    return args


def outcome(argv: list[str]) -> str:
    """Run the command line in this process: "ok" (exit 0), "refused" (exit 2, one line on stderr is the
    caller's to check), or an exception propagates: the traceback a user would have seen."""
    import arsim.cli as cli

    try:
        status = cli.main(argv)
    except SystemExit as exc:  # argparse's refusals
        status = exc.code
    if status not in (0, 2):
        raise AssertionError(f"arsim {' '.join(argv)} exited with {status}")
    return "ok" if status == 0 else "refused"
