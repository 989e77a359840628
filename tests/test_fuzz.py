"""Fuzzing on a bounded budget (benchmarks/fuzz.py runs the long profile): scenarios drawn from the
schema, recordings damaged file by file, HDR files with damaged headers and the options of every command
either load or are refused with one line (C libraries' lines counted too), before any output; nothing
else escapes."""

import shutil

import pytest
from hypothesis import HealthCheck, given, settings

from arsim.core.errors import ArsimError
from arsim.scenario.loader import parse_scenario
from tests.conftest import ENVMAPS
from tests.fuzzing import (
    bake_options,
    check_command,
    command_options,
    hdr_files,
    outcome,
    prepare_inputs,
    quiet_outcome,
    recording_mutations,
    scenario_texts,
)


@settings(max_examples=400, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(scenario_texts())
def test_a_fuzzed_scenario_loads_or_is_refused_in_one_line(text):
    try:
        parse_scenario(text, "fuzz.toml")
    except ArsimError as exc:
        assert "\n" not in str(exc).strip(), str(exc)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return prepare_inputs(tmp_path_factory.mktemp("fuzzinputs"))


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mutate=recording_mutations())
def test_a_damaged_recording_is_read_or_refused_in_one_line(inputs, tmp_path_factory, mutate):
    rec = tmp_path_factory.mktemp("mut") / "rec"
    shutil.copytree(inputs["rec"], rec, ignore=shutil.ignore_patterns("plots"))
    what = mutate(rec)
    result, lines = quiet_outcome(["info", str(rec)])  # (libpng's own lines on fd 2 counted too)
    assert result == "ok" or len(lines) == 1, (what, lines)


@settings(max_examples=100, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(file=hdr_files())
def test_a_damaged_hdr_file_is_read_or_refused_in_one_line(tmp_path_factory, file):
    suffix, data = file
    path = tmp_path_factory.mktemp("hdr") / f"f{suffix}"
    path.write_bytes(data)
    result, lines = quiet_outcome(["info", str(path)])
    assert result == "ok" or len(lines) == 1, (data[:80], lines)


def test_fuzzed_options_of_every_command_are_refused_in_one_line_before_any_output(inputs, tmp_path_factory):
    @settings(max_examples=150, deadline=None, derandomize=True, database=None)
    @given(argv=command_options(inputs))
    def run(argv):
        check_command(argv, tmp_path_factory.mktemp("cmd") / "out")

    run()


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(options=bake_options())
def test_fuzzed_bake_options_bake_or_are_refused_in_one_line(tmp_path_factory, capsys, options):
    out = tmp_path_factory.mktemp("bake") / "maps"
    result = outcome(["bake", str(ENVMAPS[0]), "-o", str(out), "--size", "16", *options])
    err = capsys.readouterr().err.strip().splitlines()
    assert result == "ok" or (len(err) == 1 and not out.exists()), (options, err)


def test_regression_an_integer_no_float_holds_for_a_number_key():
    # found by test_a_fuzzed_scenario_loads_or_is_refused_in_one_line: OverflowError escaped
    with pytest.raises(ArsimError, match=r"\[profile\] budget_ms .* wrong type"):
        parse_scenario("[profile]\nbudget_ms = " + "2" * 330 + "\n", "fuzz.toml")


def test_regression_a_path_with_control_characters_is_refused_on_one_line():
    # found by benchmarks/fuzz.py: a newline inside a path made a refusal of many lines
    with pytest.raises(ArsimError) as info:
        parse_scenario('[environment]\nmap = "a\\nb\\fc.exr"\n', "fuzz.toml")
    assert "\n" not in str(info.value) and "a\\nb\\x0cc.exr" in str(info.value)


def test_regression_a_huge_integer_in_meta_json_is_refused(tmp_path):
    # found by benchmarks/fuzz.py: OverflowError escaped the meta.json checks
    import json

    from arsim.sensors.recording import check_meta

    meta = {"format": "arsim-recording/1", "seed": 0, "duration_s": 10 ** 400}
    with pytest.raises(ArsimError, match="duration_s is not a positive number"):
        check_meta(json.loads(json.dumps(meta)), tmp_path / "meta.json")
    meta |= {"duration_s": 1.0, "camera": {"width": 8, "height": 8, "fx": 1, "fy": 1, "cx": 4, "cy": 4, "k1": 0, "k2": 0,
                                           "fps": 30}, "camera_to_device": [[10 ** 400, 0, 0], [0, 1, 0], [0, 0, 1]]}
    with pytest.raises(ArsimError, match="camera_to_device is not a 3 x 3 rotation matrix"):
        check_meta(meta, tmp_path / "meta.json")
