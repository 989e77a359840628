"""Hypothesis strategies for adversarial inputs, drawn from what arsim declares: scenarios from the
schema's sections (each key's type, range and choices, then values just outside them and values of the
wrong kind), recordings mutated file by file, HDR files with damaged headers and data, and command-line
options of every command. Used by tests/test_fuzz.py (a bounded budget) and benchmarks/fuzz.py (the long
profile)."""

from __future__ import annotations

import contextlib
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
    caller's to check), "reached work" (a stage stubbed by stub_stages was called), or an exception
    propagates: the traceback a user would have seen."""
    import arsim.cli as cli

    try:
        status = cli.main(argv)
    except SystemExit as exc:  # argparse's refusals
        status = exc.code
    except ReachedWork:
        return "reached work"
    if status not in (0, 2):
        raise AssertionError(f"arsim {' '.join(argv)} exited with {status}")
    return "ok" if status == 0 else "refused"


def quiet_outcome(argv: list[str]) -> tuple[str, list[str]]:
    """outcome, with everything printed on fds 1 and 2 (a C library's lines too) captured: (outcome, lines)."""
    from arsim.core.hdr_io import _captured_output

    with _captured_output() as lines:
        result = outcome(argv)
    return result, [line for line in lines if line]


# --------------------------------------------------------------------------------------------------
# HDR files


def _sample_image(suffix: str) -> bytes:
    """A small real image file's bytes, written by arsim (the base the mutations damage)."""
    import tempfile

    import numpy as np

    from arsim.core.hdr_io import write_image

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"s{suffix}"
        write_image(path, np.random.default_rng(1).random((16, 32, 3)).astype(np.float32) * 4)
        return path.read_bytes()


_SAMPLES: dict[str, bytes] = {}
NUMBERS = st.one_of(st.integers(-5, 40), st.sampled_from([0, 1, 16, 32, 65535, 2 ** 31, 2 ** 32 - 1, 10 ** 12, 10 ** 30]))


@st.composite
def hdr_files(draw) -> tuple[str, bytes]:
    """(suffix, bytes) of an HDR file as a disk, a tool or a person damages it: a Radiance header with odd
    lines, sizes and orders over real or junk pixels, or a real OpenEXR file cut, flipped or with a
    header field overwritten by an absurd number."""
    import struct

    if draw(st.booleans()):
        magic = draw(st.sampled_from(["#?RADIANCE", "#?RGBE", "#?", "#!RADIANCE"]))
        lines = draw(st.lists(st.one_of(st.sampled_from(["FORMAT=32-bit_rle_rgbe", "FORMAT=32-bit_rle_xyze", "FORMAT=",
                                                         "EXPOSURE=1.0", "EXPOSURE=nan", "EXPOSURE=-1e308", "GAMMA=2.2"]),
                                        st.text(max_size=20).map(lambda t: t.replace("\n", " "))), max_size=4))
        axes = draw(st.sampled_from([("-Y", "+X"), ("+Y", "+X"), ("-Y", "-X"), ("+X", "-Y"), ("-X", "+Y"), ("-Y", "-Y"), ("Y", "X")]))
        size = f"{axes[0]} {draw(NUMBERS)} {axes[1]} {draw(NUMBERS)}"
        if draw(st.integers(0, 5)) == 0:
            size = draw(st.text(max_size=16)).replace("\n", " ")
        sample = _SAMPLES.setdefault(".hdr", _sample_image(".hdr"))
        pixels = sample[sample.index(b"+X 32\n") + 6:]
        body = draw(st.one_of(st.just(pixels), st.binary(max_size=256),
                              st.integers(0, len(pixels)).map(lambda k: pixels[:k])))
        blank = "" if draw(st.integers(0, 9)) == 0 else "\n"
        header = "\n".join([magic, *lines]) + "\n" + blank + size + "\n"
        return draw(st.sampled_from([".hdr", ".exr"])), header.encode("utf-8", "replace") + body
    data = bytearray(_SAMPLES.setdefault(".exr", _sample_image(".exr")))
    kind = draw(st.sampled_from(["cut", "flip", "number", "junk"]))
    k = draw(st.integers(0, len(data) - 1)) if draw(st.booleans()) else draw(st.integers(4, min(400, len(data) - 1)))
    if kind == "cut":
        data = data[:k]
    elif kind == "flip":
        data[k] ^= draw(st.integers(1, 255))
    elif kind == "number":
        data[k:k + 4] = struct.pack("<i", draw(st.sampled_from([-1, 0, 2 ** 31 - 1, -(2 ** 31), 2 ** 24, 65537])))
    else:
        data[k:k] = draw(st.binary(min_size=1, max_size=32))
    return draw(st.sampled_from([".exr", ".hdr"])), bytes(data)


# --------------------------------------------------------------------------------------------------
# Options of every command


class ReachedWork(Exception):
    """Raised by a stubbed stage: the command's checks passed and its work would have begun."""


# the stages the commands call once their checks pass (stubbed: a fuzzed option that passes every check
# would start a minute-long run; what is fuzzed is that every check refuses in one line, before any output)
STAGES = ("arsim.run.stages.recorded", "arsim.run.stages.measured_capture", "arsim.run.stages.captured_sweep",
          "arsim.run.stages.render_session", "arsim.run.stages.profile_session", "arsim.run.pipeline.run_scenario",
          "arsim.run.batch.run_batch", "arsim.evaluate.prt_compare.prt_study")


@contextlib.contextmanager
def stub_stages():
    """Within: each of STAGES raises ReachedWork when called."""
    import importlib

    def reached(*args, **kwargs):
        raise ReachedWork

    saved = []
    for dotted in STAGES:
        module, name = dotted.rsplit(".", 1)
        mod = importlib.import_module(module)
        saved.append((mod, name, getattr(mod, name)))
        setattr(mod, name, reached)
    try:
        yield
    finally:
        for mod, name, value in saved:
            setattr(mod, name, value)


def _paths(inputs: dict[str, str]) -> st.SearchStrategy:
    """A path option's value: one of the prepared inputs (good and bad), or junk."""
    return st.one_of(st.sampled_from(sorted(inputs.values())), st.sampled_from(["", "nosuch.exr", "/", "a\x00b"]))


def command_options(inputs: dict[str, str]) -> st.SearchStrategy:
    """argv of one command (-o left to the caller): convert, diff, compare-methods, capture, render, profile,
    run, batch, validate or prt compare, with options drawn from their flags, values fuzzed; `inputs` names prepared files
    ("env", "png", "rec", "maps", "run", ...) so that some values are good."""
    numbers, path = OPTION_VALUES, _paths(inputs)
    # sizes and orders that run in a second (a 512² comparison is a long job, not a bug), or are refused
    small = st.sampled_from(["8", "16", "4", "12", "0", "-3", "x", "", "nan", "1e308", "99999", "5000", "2,1e9"])
    flags = {
        "convert": {"--layout": st.sampled_from(["anglemap", "equirect", "cube", ""]), "--size": small,
                    "--nan": st.sampled_from(["refuse", "zero", "x"])},
        "diff": {"--max-flip": numbers},
        "compare-methods": {"--methods": st.sampled_from(["fast,sh", "mc", "nope", ",", ""]), "--sh-orders": small,
                            "--reference-texels": numbers, "--spec": numbers},
        "capture": {"--size": numbers, "--align-every": numbers},
        "render": {"--env": path, "--maps": path, "--method": st.sampled_from(["fast", "sh", "nope"]), "--map-size": numbers,
                   "--key": numbers, "--white": numbers, "--every": numbers, "--log-average": st.none(), "--overlay": st.none()},
        "profile": {"--env": path, "--budget-ms": numbers, "--tile": numbers, "--sweep": numbers,
                    "--bake": st.sampled_from(["accurate", "fast", "nope"]), "--max-frames": numbers, "--map-size": numbers},
        "run": {"--recording": path, "--baseline": path, "--update-baseline": st.none(), "--keep-recording": st.none(), "--max-flip": numbers},
        "batch": {"--workers": numbers, "--ray": st.sampled_from(["auto", "127.0.0.1:1", "x", ":", "host:port"]),
                  "--baselines": path, "--max-flip": numbers},
        "validate": {},
        "prt": {"--env": path, "--order": small, "--samples": numbers,
                "--variants": st.sampled_from(["gs,sep", "sal", "nope", ",", ""])},
    }
    scenario = st.one_of(st.sampled_from(["quick", "indoor", "nosuch", inputs["scenario"], inputs["env"], inputs["rec"], ""]),
                         st.none())
    positional = {"convert": st.tuples(path, st.sampled_from([inputs["out_exr"], inputs["out_png"], inputs["out_txt"]])).map(list),
                  "diff": st.tuples(path, path).map(list),
                  "compare-methods": st.tuples(path, st.sampled_from(["8", "16", "12", "0", "x"])).map(lambda p: [p[0], "--size", p[1]]),
                  "capture": st.one_of(path, scenario).map(lambda p: [] if p is None else [p]),
                  "batch": st.lists(scenario.filter(lambda s: s is not None), min_size=1, max_size=2),
                  "prt": st.just(["compare"])}

    @st.composite
    def draw_argv(draw) -> list[str]:
        command = draw(st.sampled_from(sorted(flags)))
        args = [command, *draw(positional.get(command, scenario.map(lambda s: [] if s is None else [s]))), ]
        names = draw(st.lists(st.sampled_from(sorted(flags[command])), unique=True, max_size=3)) if flags[command] else []
        for name in names:
            value = draw(flags[command][name])
            args.append(name if value is None else f"{name}={value}")
        return args

    return draw_argv()


# a sweep of 2 s at 96 x 72 without the AR path: the recording the mutations start from
TINY_SCENARIO = ('[run]\nseed = 3\n[environment]\nmap = "envmaps/courtyard.exr"\nprobe_size = 128\n'
                 "[capture]\nduration_s = 2.0\n[device.camera]\nwidth = 96\nheight = 72\n[ar]\nenabled = false\n")


def prepare_inputs(folder: Path) -> dict[str, str]:
    """Good inputs for the fuzzed commands, made once in folder: a scenario, a small recording, an HDR
    environment, a PNG, a bake folder, and output file names for convert."""
    import subprocess
    import sys

    import numpy as np

    from arsim.core.hdr_io import write_image
    from arsim.core.png import png_bytes

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "s.toml").write_text(TINY_SCENARIO)
    env = folder / "env.exr"
    write_image(env, np.random.default_rng(2).random((16, 32, 3)).astype(np.float32) * 4)
    (folder / "a.png").write_bytes(png_bytes(np.full((8, 8, 3), 90, np.uint8)))
    for command in (["record", str(folder / "s.toml"), "-o", str(folder / "rec")],
                    ["bake", str(env), "-o", str(folder / "maps"), "--size", "16", "--spec", "1,10"]):
        subprocess.run([sys.executable, "-m", "arsim", *command], check=True, capture_output=True)
    return {"scenario": str(folder / "s.toml"), "rec": str(folder / "rec"), "env": str(env), "png": str(folder / "a.png"),
            "maps": str(folder / "maps"), "out_exr": str(folder / "out" / "c.exr"), "out_png": str(folder / "c.png"),
            "out_txt": str(folder / "c.txt")}


def check_command(argv: list[str], out: Path) -> str:
    """Run a fuzzed command line (with -o out where it takes one) with its stages stubbed: its outcome,
    after checking that a refusal is one line and left no output behind. AssertionError otherwise."""
    takes_output = argv[0] not in ("convert", "validate")
    full = argv + (["-o", str(out)] if takes_output else [])
    written = [out] if takes_output else [Path(argv[2])] if argv[0] == "convert" and len(argv) > 2 else []
    def state(path: Path):
        return path.read_bytes() if path.is_file() else "folder" if path.is_dir() else None

    before = {p: state(p) for p in written}  # (a file there may be an earlier case's convert output)
    with stub_stages():
        result, lines = quiet_outcome(full)
    if result == "refused":
        if len(lines) != 1:
            raise AssertionError(f"a refusal of {len(lines)} lines: {lines[:3]}")
        left = [str(p) for p in written if state(p) != before[p]]
        if left or list(out.parent.glob(f".{out.name}.*")):
            raise AssertionError(f"a refusal left {left or 'a temporary folder'} behind")
    return result
