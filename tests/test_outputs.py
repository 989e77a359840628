"""Output folders: a command's output appears whole or not at all, replaces an earlier arsim output
whole (old and new files never mix), and never replaces what arsim did not write unless --force."""

import errno
import os
import signal
import socket
import subprocess
import sys
import time

import arsim.cli as cli
from arsim.core.files import OUTPUT_MARK
from arsim.scenario.loader import scenario_path
from tests.conftest import ENVMAPS
from tests.test_cli import arsim, assert_one_line_error

ENV = ENVMAPS[0]


def _bake(out, *options, cwd=None):
    return arsim("bake", ENV, "-o", out, "--size", "16", *options, cwd=cwd)


def test_a_second_command_replaces_the_first_ones_output_whole(tmp_path):
    out = tmp_path / "maps"
    assert _bake(out, "--spec", "1,10").returncode == 0
    assert {p.name for p in out.iterdir()} == {OUTPUT_MARK, "bake.json", "irradiance.exr", "reflection_s10.exr"}
    assert _bake(out, "--spec", "1").returncode == 0
    # the exponent 10 of the first bake is gone: the folder holds one bake, not a mix of two
    assert {p.name for p in out.iterdir()} == {OUTPUT_MARK, "bake.json", "irradiance.exr"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["maps"]  # no temporary or old folder left beside it


def test_a_folder_of_other_files_is_refused_unless_forced(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    assert_one_line_error(_bake(out), "holds files arsim did not write", "--force")
    assert (out / "notes.txt").read_text() == "keep me"
    assert _bake(out, "--spec", "1", "--force").returncode == 0
    assert {p.name for p in out.iterdir()} == {OUTPUT_MARK, "bake.json", "irradiance.exr"}
    (tmp_path / "empty").mkdir()
    assert _bake(tmp_path / "empty", "--spec", "1").returncode == 0  # an empty folder is taken as it is


def test_the_folder_one_is_in_or_one_holding_an_input_is_refused(tmp_path):
    assert_one_line_error(_bake(".", cwd=tmp_path), "is the folder you are in")
    assert_one_line_error(_bake(tmp_path.parent, cwd=tmp_path), "is the folder you are in")
    assert _bake(tmp_path / "maps", "--spec", "1").returncode == 0
    assert_one_line_error(arsim("bake", tmp_path / "maps" / "irradiance.exr", "-o", tmp_path / "maps", "--size", "16"),
                          "holds the input")
    assert (tmp_path / "maps" / "irradiance.exr").is_file()


def test_a_failure_midway_leaves_the_earlier_output_as_it_was(tmp_path, monkeypatch, capsys):
    out = tmp_path / "maps"
    assert _bake(out, "--spec", "1,10").returncode == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def fill_the_disk(folder, *args, **kwargs):
        (folder / "irradiance.exr").write_bytes(b"half")  # a file written before the disk filled
        raise OSError(errno.ENOSPC, "No space left on device", str(folder / "reflection_s10.exr"))

    monkeypatch.setattr("arsim.cli.write_bake", fill_the_disk)
    assert cli.main(["bake", str(ENV), "-o", str(out), "--size", "16", "--spec", "1,10"]) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["maps"]


def test_a_killed_command_leaves_nothing_under_the_name_and_its_leftovers_are_cleaned(tmp_path):
    out = tmp_path / "maps"
    # a bake of many exponents, killed once it writes into its temporary folder
    proc = subprocess.Popen([sys.executable, "-m", "arsim", "bake", str(ENV), "-o", str(out), "--size", "64",
                             "--method", "accurate", "--spec", "1,2,4,8,16,32,64,128"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".maps.tmp-*")) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not out.exists()
    leftovers = list(tmp_path.glob(".maps.tmp-*"))
    assert len(leftovers) == 1
    # a temporary folder of a process still running (this one) is left alone; a dead one's is removed
    alive = tmp_path / f".maps.tmp-{socket.gethostname()}.{os.getpid()}.x"
    alive.mkdir()
    assert _bake(out, "--spec", "1").returncode == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["maps", alive.name])


def test_a_bundled_scenarios_name_still_names_it_when_a_folder_has_that_name(tmp_path, monkeypatch):
    # `arsim run quick -o quick` a second time: the folder quick is the first run's output, not a scenario
    monkeypatch.chdir(tmp_path)
    (tmp_path / "quick").mkdir()
    assert scenario_path("quick").name == "quick.toml" and scenario_path("quick").is_file()
    (tmp_path / "indoor").write_text("[run]\n")  # a file of that name is the scenario named
    assert scenario_path("indoor") == tmp_path.joinpath("indoor").relative_to(tmp_path)


def test_a_full_disk_midway_through_a_recording_leaves_no_half_recording(tmp_path, monkeypatch, capsys):
    # the disk fills after the frames, before the IMU streams: a half recording used to stay behind
    from tests.fuzzing import TINY_SCENARIO

    (tmp_path / "s.toml").write_text(TINY_SCENARIO)

    def full(out_dir, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(out_dir / "imu.csv"))

    monkeypatch.setattr("arsim.sensors.recording._write_streams", full)
    assert cli.main(["record", str(tmp_path / "s.toml"), "-o", str(tmp_path / "rec")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "imu.csv: No space left on device" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_json_text_encodes_numpy_values_and_writes_non_finite_figures_as_null():
    """json_text at once where every number is finite (NumPy arrays and scalars as they come) and through the strict
    conversion where one is not: the same text as the strict conversion either way, null for NaN and infinities."""
    import json

    import numpy as np

    from arsim.core.files import _strict, json_text

    rng = np.random.default_rng(0)
    values = [
        {"a": np.float32(1.1), "b": np.arange(5), "c": (1, 2.5, np.int64(3)), "d": [np.bool_(True), None, "x"],
         5: np.array([[1.5, 2.25]]), "e": np.array([], dtype=float), "f": (np.uint8(7), np.float16(0.5))},
        {"x": float("nan"), "y": np.array([1.0, np.inf]), "z": {"w": np.float64(-np.inf)}},
        [np.float64(0.1), 1e300, -0.0, np.array(3.0), rng.random((4, 3))],
    ]
    for value in values:
        for indent in (2, None):
            assert json_text(value, indent) == json.dumps(_strict(value), indent=indent, allow_nan=False) + "\n"
    assert json.loads(json_text(values[1])) == {"x": None, "y": [1.0, None], "z": {"w": None}}
    assert json.loads(json_text(values[0]))["b"] == [0, 1, 2, 3, 4]
