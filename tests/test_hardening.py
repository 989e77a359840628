"""Bad input and a hostile machine, as an adversarial user meets them: each ends in one line and exit
status 2 (no traceback), before any output folder is made; gates refuse a tolerance that passes anything."""

import errno

import pytest

import arsim.cli as cli
from tests.conftest import ENVMAPS
from tests.test_cli import arsim, assert_one_line_error

ENV = ENVMAPS[0]


@pytest.mark.parametrize("options, fragment", [
    (["--spec", "1e308"], "up to 1e+06"),
    (["--method", "mc", "--seed", "-1"], "--seed -1 is negative"),
    (["--method", "mc", "--samples", "1000000000"], "GiB per texel"),
    (["--method", "sh", "--sh-order", "100000"], "SH order 100000"),
])
def test_bake_refuses_an_option_out_of_range_before_any_output(tmp_path, options, fragment):
    assert_one_line_error(arsim("bake", ENV, "-o", tmp_path / "maps", "--size", "16", *options), fragment)
    assert not (tmp_path / "maps").exists()


@pytest.mark.parametrize("orders, fragment", [("-3", "SH order -3"), ("5000", "SH order 5000"), ("x", "not a list")])
def test_compare_methods_refuses_sh_orders_out_of_range_before_any_work(tmp_path, orders, fragment):
    # 5000 grew to 20 GB before the orders were checked; now refused at once
    assert_one_line_error(arsim("compare-methods", ENV, "-o", tmp_path / "c", "--size", "16", "--sh-orders", orders), fragment)
    assert not (tmp_path / "c").exists()


def test_an_output_folder_under_a_file_or_unwritable_is_refused_in_one_line(tmp_path):
    (tmp_path / "afile").write_text("x")
    assert_one_line_error(arsim("bake", ENV, "-o", tmp_path / "afile" / "maps", "--size", "16"), "cannot write a folder in")
    assert_one_line_error(arsim("bake", ENV, "-o", "/proc/arsim-maps", "--size", "16"), "/proc/arsim-maps", "cannot write a folder in")
    assert_one_line_error(arsim("bake", ENV, "-o", tmp_path / "afile", "--size", "16"), "exists and is not a folder")
    assert (tmp_path / "afile").read_text() == "x"


def test_a_full_disk_while_writing_is_one_line_naming_the_file(tmp_path, monkeypatch, capsys):
    # the disk fills after the checks, mid-run: the OS error reaches the command line, which names the path
    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "maps" / "maps.json"))

    monkeypatch.setattr("arsim.cli.write_bake", full)
    status = cli.main(["bake", str(ENV), "-o", str(tmp_path / "maps"), "--size", "16", "--spec", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1
    assert "maps.json: No space left on device" in err[0]
    assert list(tmp_path.iterdir()) == []  # nothing half-written: no maps folder, no temporary one


def test_mc_memory_is_bounded_by_the_chunk_not_the_sample_count():
    # 2^16 samples per texel over an 8² map's 52 disk texels: drawn for all texels at once, the peak
    # was 0.9 GB; a chunk of CHUNK_SAMPLES samples (8 texels) keeps it near 0.13 GB
    import tracemalloc

    import numpy as np

    from arsim.lighting.mc import BYTES_PER_SAMPLE, CHUNK_SAMPLES, mc_maps

    env = np.random.default_rng(0).random((8, 8, 3)).astype(np.float32)
    tracemalloc.start()
    try:
        maps = mc_maps(env, [10.0], samples=1 << 16, seed=1)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert np.isfinite(maps).all() and maps.max() > 0
    assert peak < 1.5 * CHUNK_SAMPLES * BYTES_PER_SAMPLE, peak


@pytest.mark.parametrize("toml, fragment", [
    ("[device.camera]\nexposure_min_s = 0.02\nexposure_max_s = 0.01\n", "exposure_min_s = 0.02 is above exposure_max_s"),
    ("[device.camera]\niso_min = 800\niso_max = 100\n", "iso_min = 800 is above iso_max = 100"),
    ("[ar]\nnear_m = 2.0\nfar_m = 1.0\n", "far_m = 1.0 is below near_m = 2.0"),
    ("[[ar.look_away]]\nstart_s = 5.0\nend_s = 4.0\n", "start_s = 5.0 is not before end_s = 4.0"),
    ('[[render.objects]]\nkind = "mesh"\n', 'kind = "mesh" needs mesh'),
    ('[environment]\nmap = "envmaps"\n', "a folder, not a file"),
    ('[environment]\nmap = "~nosuchuser/x.exr"\n', "is not a usable path"),
    ('[environment]\nmap = "a\\u0000b.exr"\n', "is not a usable path"),
    ('[environment]\nmap = "' + "a" * 300 + '.exr"\n', "is not a usable path"),
    ("[run]\nseed = " + "1" * 400 + "\n", "out of range"),
])
def test_validate_refuses_what_a_later_stage_would(tmp_path, toml, fragment):
    # each of these passed `validate` and failed later (or crashed) before the rules moved into the schema
    (tmp_path / "s.toml").write_text(toml)
    assert_one_line_error(arsim("validate", tmp_path / "s.toml"), fragment)


@pytest.mark.parametrize("size_line, fragment", [
    ("-Y 999999999 +X 999999999", "16384 x 8192"),  # cv2.error escaped: larger than OpenCV reads
    ("-Y 100000 +X 100000", "16384 x 8192"),
    ("-Y 400 +X 5", "is truncated"),  # 400 scanlines in 64 bytes: refused before a decoder allocates them
    ("size", "no Radiance resolution line"),
])
def test_a_radiance_file_with_an_absurd_size_line_is_refused_in_one_line(tmp_path, size_line, fragment):
    path = tmp_path / "h.hdr"
    path.write_bytes(f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n{size_line}\n".encode() + bytes(range(64)))
    assert_one_line_error(arsim("info", path), fragment)


def test_a_corrupted_frame_is_one_line_without_libpngs_own(tmp_path):
    # libpng printed "libpng error: IDAT: incorrect data check" on fd 2 before arsim's refusal
    from tests.fuzzing import prepare_inputs

    rec = prepare_inputs(tmp_path / "in")["rec"]
    frame = sorted((tmp_path / "in" / "rec" / "frames").glob("*.png"))[3]
    data = bytearray(frame.read_bytes())
    data[-20] ^= 0xFF  # inside the last IDAT: its CRC no longer matches
    frame.write_bytes(bytes(data))
    assert_one_line_error(arsim("info", rec), frame.name, "fails its CRC")
    data[-20] ^= 0xFF
    frame.write_bytes(bytes(data[: len(data) // 2]))
    assert_one_line_error(arsim("info", rec), frame.name, "is truncated")
