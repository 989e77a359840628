"""The command line: each command works on every asset; every bad input is one line and exit status 2."""

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from arsim import __version__
from arsim.core.conventions import direction_to_anglemap_st, equirect_uv_to_direction
from arsim.core.hdr_io import read_hdr, write_exr
from tests.conftest import ENVMAPS


def arsim(*args, cwd=None, env=None):
    return subprocess.run([sys.executable, "-m", "arsim", *map(str, args)], capture_output=True, text=True, cwd=cwd, env=env)


def assert_one_line_error(result, *fragments):
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def test_version():
    r = arsim("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"arsim {__version__}"


@pytest.mark.parametrize("command", ["info", "convert", "validate"])
def test_every_command_has_help_with_an_example(command):
    r = arsim(command, "--help")
    assert r.returncode == 0 and "example:" in r.stdout and f"arsim {command}" in r.stdout


@pytest.mark.parametrize("path", ENVMAPS, ids=lambda p: p.stem)
def test_info_and_convert_run_on_every_asset(tmp_path, path):
    r = arsim("info", path, "--json")
    assert r.returncode == 0, r.stderr
    stats = json.loads(r.stdout)
    assert stats["layout"] == "equirect" and (stats["width"], stats["height"]) == (1024, 512)
    assert stats["nan"] == 0 and stats["inf"] == 0 and stats["max"] > stats["mean"] > 0
    for out, args in [("am.exr", ["--layout", "anglemap", "--size", "256"]), ("am.png", ["--layout", "anglemap"]),
                      ("eq.hdr", ["--size", "128"]), ("eq.png", [])]:
        r = arsim("convert", path, tmp_path / out, *args)
        assert r.returncode == 0, r.stderr
        assert (tmp_path / out).stat().st_size > 0
    assert read_hdr(tmp_path / "am.exr").shape == (256, 256, 3)
    assert read_hdr(tmp_path / "eq.hdr").shape == (128, 256, 3)
    assert cv2.imread(str(tmp_path / "am.png")).shape == (512, 512, 3)
    r = arsim("info", tmp_path / "am.exr")
    assert r.returncode == 0 and "angle map 1:1" in r.stdout


def test_info_text_output():
    r = arsim("info", ENVMAPS[0])
    assert r.returncode == 0
    assert "1024 x 512 (equirect 2:1" in r.stdout and "NaN 0  Inf 0" in r.stdout


def test_convert_puts_a_bright_spot_at_the_texel_the_convention_gives(tmp_path):
    h, n = 128, 256
    row, col = 40, 170
    eq = np.full((h, 2 * h, 3), 0.05, dtype=np.float32)
    eq[row, col] = 500.0
    write_exr(tmp_path / "spot.exr", eq)
    r = arsim("convert", tmp_path / "spot.exr", tmp_path / "spot_am.exr", "--layout", "anglemap", "--size", n)
    assert r.returncode == 0, r.stderr
    am = read_hdr(tmp_path / "spot_am.exr")
    d = equirect_uv_to_direction(np.array([(col + 0.5) / (2 * h), (row + 0.5) / h]))
    s, t = direction_to_anglemap_st(d)
    expected = (int((1 - t) * n), int(s * n))  # row 0 is the top: t = 1
    peak = np.unravel_index(np.argmax(am[..., 1]), am.shape[:2])
    assert abs(peak[0] - expected[0]) <= 1 and abs(peak[1] - expected[1]) <= 1, (peak, expected)


def test_convert_nan_is_refused_by_default_and_replaced_on_request(tmp_path):
    img = np.ones((16, 32, 3), dtype=np.float32)
    img[3, 4] = np.nan
    img[5, 6, 2] = np.inf
    write_exr(tmp_path / "nan.exr", img)
    r = arsim("convert", tmp_path / "nan.exr", tmp_path / "out.exr")
    assert_one_line_error(r, "2 texels are NaN or Inf", "--nan zero")
    assert not (tmp_path / "out.exr").exists()
    r = arsim("convert", tmp_path / "nan.exr", tmp_path / "out.exr", "--nan", "zero")
    assert r.returncode == 0 and "replaced 2 NaN/Inf texels with 0" in r.stdout
    out = read_hdr(tmp_path / "out.exr")
    assert np.isfinite(out).all() and np.all(out[3, 4] == 0)
    r = arsim("info", tmp_path / "nan.exr")
    assert r.returncode == 0 and "NaN 1  Inf 1" in r.stdout


def bad_inputs(tmp_path):
    """(name, arguments, fragments the one-line message must contain)."""
    (tmp_path / "text.exr").write_text("not an image at all")
    data = ENVMAPS[0].read_bytes()
    (tmp_path / "cut.exr").write_bytes(data[: len(data) // 2])
    write_exr(tmp_path / "odd.exr", np.ones((30, 50, 3), np.float32))
    cv2.imwrite(str(tmp_path / "ldr.png"), np.zeros((8, 16, 3), np.uint8))
    (tmp_path / "typo.toml").write_text("[environment]\nprobe_sise = 256\n")
    (tmp_path / "range.toml").write_text("[environment]\nprobe_size = 100000\n")
    (tmp_path / "nofile.toml").write_text("[environment]\nmap = 'missing.exr'\n")
    good = ENVMAPS[0]
    return [
        ("missing file", ["info", tmp_path / "nope.exr"], ["no such file"]),
        ("not an image", ["info", tmp_path / "text.exr"], ["not an HDR image"]),
        ("8-bit image", ["convert", tmp_path / "ldr.png", tmp_path / "o.exr"], ["8-bit PNG"]),
        ("truncated exr", ["info", tmp_path / "cut.exr"], ["truncated or corrupt"]),
        ("odd aspect", ["convert", tmp_path / "odd.exr", tmp_path / "o.exr"], ["50x30", "neither 1:1", "2:1"]),
        ("odd aspect info", ["info", tmp_path / "odd.exr"], ["neither 1:1"]),
        ("unknown output type", ["convert", good, tmp_path / "o.jpg"], ["unknown output type", ".exr, .hdr or .png"]),
        ("missing output folder", ["convert", good, tmp_path / "no" / "o.exr"], ["does not exist"]),
        ("bad size", ["convert", good, tmp_path / "o.exr", "--size", "-3"], ["--size", "out of range"]),
        ("bad layout", ["convert", good, tmp_path / "o.exr", "--layout", "cube"], ["invalid choice", "cube"]),
        ("mistyped key", ["validate", tmp_path / "typo.toml"], ["unknown key 'probe_sise'", "did you mean 'probe_size'"]),
        ("out of range", ["validate", tmp_path / "range.toml"], ["probe_size = 100000", "from 16 to 4096"]),
        ("scenario file missing", ["validate", tmp_path / "nope.toml"], ["no such scenario file"]),
        ("scenario path missing", ["validate", tmp_path / "nofile.toml"], ["missing.exr", "no such file"]),
        ("unknown command", ["bake-it"], ["invalid choice"]),
    ]


def test_bad_inputs_give_one_line_and_exit_status_2(tmp_path):
    for name, args, fragments in bad_inputs(tmp_path):
        r = arsim(*args)
        try:
            assert_one_line_error(r, *fragments)
        except AssertionError as exc:
            raise AssertionError(f"{name}: {exc}") from None
    assert not list(tmp_path.glob("o.*")) and not list(tmp_path.glob(".*tmp*"))


def test_validate_prints_the_resolved_default_scenario():
    r = arsim("validate")
    assert r.returncode == 0
    assert "[environment]" in r.stdout and "interior.exr" in r.stdout and "probe_size = 512" in r.stdout


@pytest.mark.parametrize("command", ["validate", "run", "batch"])
def test_a_map_size_not_a_power_of_two_is_refused_where_the_scenario_is_read(tmp_path, command):
    scenario = tmp_path / "maps.toml"
    scenario.write_text("[render]\nmap_size = 100\n")
    out = tmp_path / "out"
    result = arsim(command, scenario, *(() if command == "validate" else ("-o", out)))
    assert_one_line_error(result, "[render] map_size = 100", "power of two")
    assert not out.exists()
