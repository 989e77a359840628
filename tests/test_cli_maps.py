"""arsim bake and arsim compare-methods: the files they write, and one-line errors for bad input."""

import csv
import json

import numpy as np
import pytest

from arsim.core.files import OUTPUT_MARK
from arsim.core.hdr_io import read_hdr, write_exr
from tests.conftest import ENVMAPS
from tests.test_cli import arsim, assert_one_line_error


@pytest.fixture(scope="module")
def probe32(tmp_path_factory):
    path = tmp_path_factory.mktemp("probe") / "probe32.exr"
    r = arsim("convert", ENVMAPS[1], path, "--layout", "anglemap", "--size", "32")
    assert r.returncode == 0, r.stderr
    return path


def test_bake_writes_the_maps_and_bake_json(tmp_path, probe32):
    r = arsim("bake", probe32, "-o", tmp_path / "maps", "--method", "fast", "--spec", "1,10,80,2.5")
    assert r.returncode == 0, r.stderr
    names = sorted(p.name for p in (tmp_path / "maps").iterdir() if p.name != OUTPUT_MARK)
    assert names == ["bake.json", "irradiance.exr", "reflection_s10.exr", "reflection_s2.5.exr", "reflection_s80.exr"]
    record = json.loads((tmp_path / "maps" / "bake.json").read_text())
    assert record["method"] == "fast" and record["size"] == 32
    assert set(record["maps"]) == set(names) - {"bake.json"}
    assert record["seconds_total"] >= sum(m["seconds"] for m in record["maps"].values())
    irradiance = read_hdr(tmp_path / "maps" / "irradiance.exr")
    assert irradiance.shape == (32, 32, 3) and np.isfinite(irradiance).all() and irradiance.max() > 0


def test_bake_sht_sums_a_larger_equirect_at_its_own_resolution(tmp_path):
    from arsim.core.resample import to_layout
    from arsim.lighting.methods import bake
    from arsim.lighting.sht import sht_maps_from_source

    equirect = read_hdr(ENVMAPS[1])[::8, ::8].astype(np.float32)  # 64 x 128: more texels than a 32² map
    equirect[20, 70] += 500.0  # a small bright source, which resampling to 32² would thin out
    write_exr(tmp_path / "probe.exr", equirect)
    r = arsim("bake", tmp_path / "probe.exr", "-o", tmp_path / "maps", "--method", "sht", "--size", "32", "--spec", "1,80")
    assert r.returncode == 0, r.stderr
    record = json.loads((tmp_path / "maps" / "bake.json").read_text())
    assert record["summed_over"] == "equirect 128x64 at its own resolution"
    got = read_hdr(tmp_path / "maps" / "reflection_s80.exr")
    source = read_hdr(tmp_path / "probe.exr")
    np.testing.assert_allclose(got, sht_maps_from_source(source, 32, [80])[0], rtol=1e-6, atol=1e-6 * got.max())
    resampled = bake(to_layout(source, "anglemap", 32), [80], "sht").maps[0]
    assert np.abs(got - resampled).max() > 1e-3 * got.max()  # not the resampled map's sums
    # a map as large as the equirect's texel count or larger: the resampled angle map, as before
    r = arsim("bake", tmp_path / "probe.exr", "-o", tmp_path / "big", "--method", "sht", "--size", "128", "--spec", "1")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "big" / "bake.json").read_text())["summed_over"] == "angle map"


def test_bake_resamples_an_equirect_to_the_requested_size(tmp_path):
    r = arsim("bake", ENVMAPS[1], "-o", tmp_path, "--method", "mipmap", "--size", "64", "--spec", "1")
    assert r.returncode == 0, r.stderr
    assert read_hdr(tmp_path / "irradiance.exr").shape == (64, 64, 3)


def test_sh_parameters_are_recorded(tmp_path, probe32):
    r = arsim("bake", probe32, "-o", tmp_path, "--method", "sh", "--sh-order", "9", "--sh-faithful", "--spec", "1")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "bake.json").read_text())["parameters"] == {"sh_order": 9, "sh_faithful": True,
                                                                              "sh_window": "none"}
    r = arsim("bake", probe32, "-o", tmp_path / "w", "--method", "sh", "--sh-order", "9", "--sh-window", "hann",
              "--spec", "1")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "w" / "bake.json").read_text())["parameters"]["sh_window"] == "hann"


def test_mc_bakes_on_lobe_grids_unless_told_every_texel(tmp_path):
    from arsim.core.resample import to_layout
    from arsim.lighting.mc import mc_maps

    probe = tmp_path / "probe64.exr"
    write_exr(probe, to_layout(read_hdr(ENVMAPS[1]), "anglemap", 64).astype(np.float32))
    env = read_hdr(probe)
    for flags, grids in (((), True), (("--mc-texels",), False)):
        out = tmp_path / f"grids_{grids}"
        r = arsim("bake", probe, "-o", out, "--method", "mc", "--samples", "16", "--seed", "2", "--spec", "10", *flags)
        assert r.returncode == 0, r.stderr
        assert json.loads((out / "bake.json").read_text())["parameters"] == {"samples": 16, "seed": 2,
                                                                            "mc_texels": not grids}
        want = mc_maps(env, [10], 16, seed=2, grids=grids)[0]  # (s = 10 has a grid at 64²: the two differ)
        np.testing.assert_array_equal(read_hdr(out / "reflection_s10.exr"), want)
    assert not np.array_equal(read_hdr(tmp_path / "grids_True" / "reflection_s10.exr"),
                              read_hdr(tmp_path / "grids_False" / "reflection_s10.exr"))


def test_compare_methods_writes_tables_and_figures(tmp_path, probe32):
    r = arsim("compare-methods", probe32, "-o", tmp_path, "--spec", "1,20", "--methods", "fast,mipmap,sh",
              "--sh-orders", "3,6")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [OUTPUT_MARK, "methods.png", "sh_order.png", "tables.csv",
                                                          "tables.json", "tables.md"]
    tables = json.loads((tmp_path / "tables.json").read_text())
    assert set(tables["errors_percent"]) == {"fast", "mipmap", "sh"}
    assert tables["errors_percent"]["fast"][0]["mean"] < 0.5
    assert len(tables["sh_mean_error_percent_by_order"]["stable"]) == 2
    md = (tmp_path / "tables.md").read_text()
    assert "| fast (SH order 64) |" in md  # s = 1 and 20 both take the minimum, 64
    assert "| sh (order 35, window none) |" in md and "| mipmap |" in md
    # the printed table and tables.csv name the orders too
    assert "sh (order 35, window none)  mean error up to" in r.stdout and "fast (SH order 64)" in r.stdout
    rows = list(csv.DictReader((tmp_path / "tables.csv").open()))
    assert [(r["label"], r["sh_order"], r["sh_window"]) for r in rows if r["method"] == "sh"] == [
        ("sh (order 35, window none)", "35", "none")] * 2


def test_bad_map_inputs_give_one_line_and_exit_status_2(tmp_path, probe32):
    nan_env = np.ones((16, 16, 3), np.float32)
    nan_env[4, 4] = np.nan
    write_exr(tmp_path / "nan.exr", nan_env)
    write_exr(tmp_path / "odd.exr", np.ones((24, 24, 3), np.float32))
    out = tmp_path / "out"
    cases = [
        (["--spec", "1,0"], ["Phong exponent 0", "positive"]),
        (["--spec", "-5"], ["Phong exponent -5"]),
        (["--spec", "1,abc"], ["'abc' is not a number"]),
        (["--size", "100"], ["size 100", "power of two"]),
        (["--size", "4"], ["size 4", "power of two from 8"]),
        (["--sh-order", "0", "--method", "sh"], ["--sh-order 0", "at least 1"]),
        (["--method", "magic"], ["invalid choice", "magic"]),
    ]
    for extra, fragments in cases:
        assert_one_line_error(arsim("bake", probe32, "-o", out, *extra), *fragments)
    assert_one_line_error(arsim("bake", tmp_path / "nan.exr", "-o", out), "NaN or Inf")
    assert_one_line_error(arsim("bake", tmp_path / "odd.exr", "-o", out), "24", "power of two")
    assert_one_line_error(arsim("compare-methods", probe32, "-o", out, "--methods", "fast,nope"), "map method 'nope'")
    assert not out.exists() or not any(out.iterdir())
