"""Scenario files: typed, frozen, checked at the boundary; paths resolve against the file, then assets."""

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import pytest

from arsim.core.assets import scenarios_dir
from arsim.scenario import EnvironmentSection, Scenario, ScenarioError, load_scenario, scenario_to_toml
from arsim.scenario.loader import parse_scenario
from arsim.scenario.schema import PathResolver, parse_section, setting, subsection
from tests.conftest import ASSETS


def write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_default_scenario_loads_and_is_frozen():
    s = load_scenario()
    assert isinstance(s, Scenario) and isinstance(s.environment, EnvironmentSection)
    assert s.environment.map == (ASSETS / "envmaps" / "interior.exr").resolve()
    assert s.environment.map.exists()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.run.seed = 3


def test_values_are_typed_and_defaults_fill_the_rest(tmp_path):
    s = load_scenario(write(tmp_path, '[run]\nseed = 7\n[environment]\nintensity = 2\nmap = "envmaps/city.exr"\n'))
    assert s.run.seed == 7 and s.run.name == "default"
    assert s.environment.intensity == 2.0 and isinstance(s.environment.intensity, float)
    assert s.environment.probe_size == 512
    assert s.environment.map == (ASSETS / "envmaps" / "city.exr").resolve()


def test_relative_paths_resolve_against_the_scenario_file_first(tmp_path):
    (tmp_path / "envmaps").mkdir()
    local = tmp_path / "envmaps" / "city.exr"
    local.write_bytes((ASSETS / "envmaps" / "city.exr").read_bytes())
    s = load_scenario(write(tmp_path, '[environment]\nmap = "envmaps/city.exr"\n'))
    assert s.environment.map == local.resolve()


def test_resolved_scenario_round_trips_through_toml(tmp_path):
    s = load_scenario(write(tmp_path, '[environment]\nyaw_deg = 45\nmap = "envmaps/night.exr"\n'))
    again = load_scenario(write(tmp_path, scenario_to_toml(s), "again.toml"))
    assert again == s


@pytest.mark.parametrize(
    "text, message",
    [
        ("[enviroment]\nmap = 'x'\n", r"unknown section \[enviroment\]: did you mean \[environment\]\?"),
        ("[environment]\nprobe_sise = 256\n", r"\[environment\] unknown key 'probe_sise': did you mean 'probe_size'\?"),
        ("[environment]\nzzz = 1\n", r"unknown key 'zzz': \(known keys: map, probe_size, intensity, yaw_deg\)"),
        ("[environment]\nprobe_size = 8\n", r"probe_size = 8 is out of range: allowed from 16 to 4096 texels"),
        ("[environment]\nintensity = -1.0\n", r"intensity = -1.0 is out of range: allowed from 0.0 to"),
        ("[environment]\nprobe_size = 'big'\n", r'probe_size = "big" has the wrong type: expected an integer'),
        ("[environment]\nprobe_size = 256.5\n", r"probe_size = 256.5 has the wrong type: expected an integer"),
        ("[run]\nseed = true\n", r"seed = true has the wrong type: expected an integer"),
        ("[environment]\nyaw_deg = nan\n", r"yaw_deg = nan has the wrong type: expected a finite number"),
        ("[environment]\nmap = 'envmaps/nope.exr'\n", r'map = "envmaps/nope.exr": no such file \(looked for .*nope.exr'),
        ("environment = 3\n", r"'environment' must be a table"),
        ("[run\nseed = 1\n", r"is not valid TOML"),
    ],
)
def test_bad_scenarios_name_the_key_the_value_and_what_is_allowed(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError, match=message) as info:
        load_scenario(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_missing_scenario_file(tmp_path):
    with pytest.raises(ScenarioError, match="no such scenario file"):
        load_scenario(tmp_path / "nope.toml")


def test_a_scenario_that_is_not_text(tmp_path):
    path = tmp_path / "bin.toml"
    path.write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(ScenarioError, match="not a text file"):
        load_scenario(path)


# A section added by a later stage is one dataclass: nested tables and arrays of tables come for free.


@dataclass(frozen=True)
class _Light:
    colour: tuple[float, float, float] = setting((1.0, 1.0, 1.0), min=0.0, help="RGB")
    name: str = setting("key", choices=("key", "fill", "rim"), help="which light")


@dataclass(frozen=True)
class _Stage:
    mode: str = setting("fast", choices=("fast", "exact"), help="how")
    texture: Path | None = setting(None, must_exist=True, help="optional texture")
    key: _Light = subsection(_Light, help="the key light")
    lights: tuple[_Light, ...] = subsection(_Light, help="more lights", array=True)


def parse_stage(table):
    return parse_section(_Stage, table, "t.toml", PathResolver(None, ASSETS), "stage")


def test_new_sections_get_nesting_arrays_choices_and_tuples():
    s = parse_stage({"mode": "exact", "key": {"colour": [2, 3, 4]}, "lights": [{"name": "fill"}, {}]})
    assert s.mode == "exact" and s.key.colour == (2.0, 3.0, 4.0)
    assert [light.name for light in s.lights] == ["fill", "key"] and s.texture is None
    assert parse_stage({}).lights == ()


@pytest.mark.parametrize(
    "table, message",
    [
        ({"mode": "exakt"}, r'\[stage\] mode = "exakt" is not allowed: use one of "fast", "exact"; did you mean "exact"\?'),
        ({"key": {"colour": [1, 2]}}, r"\[stage.key\] colour = \[1, 2\] has the wrong type: expected an array of 3"),
        ({"key": {"colour": [1, -2, 3]}}, r"\[stage.key\] colour = .* is out of range: allowed at least 0.0"),
        ({"lights": [{}, {"nme": "rim"}]}, r"\[stage.lights\[1\]\] unknown key 'nme': did you mean 'name'\?"),
        ({"lights": {"name": "rim"}}, r"'stage.lights' must be an array of tables \(\[\[stage.lights\]\]\)"),
        ({"texture": "nope.png"}, r"texture = \"nope.png\": no such file"),
    ],
)
def test_new_sections_are_checked_as_strictly(table, message):
    with pytest.raises(ScenarioError, match=message):
        parse_stage(table)


def test_parse_scenario_from_text_uses_the_assets_for_relative_paths():
    s = parse_scenario('[environment]\nmap = "envmaps/sunrise.exr"\n')
    assert s.environment.map == (ASSETS / "envmaps" / "sunrise.exr").resolve()


@pytest.mark.parametrize("path", sorted(scenarios_dir().glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_scenarios_are_valid(path):
    s = load_scenario(path)
    assert s.environment.map.exists()


def test_one_section_class_serves_tables_with_their_own_defaults():
    s = parse_scenario("[device.magnetometer]\nnoise_density = 0.3\n")
    assert s.device.magnetometer.noise_density == 0.3
    assert s.device.magnetometer.rate_hz == 50.0  # the magnetometer's default, not the class's 200 Hz
    assert s.device.gyroscope.rate_hz == 200.0 and s.device.accelerometer.full_scale > 150.0
    # A section left out still has its default paths resolved (here the environment map).
    assert s.environment.map.is_absolute() and s.environment.map.exists()
    again = parse_scenario(scenario_to_toml(s))
    assert again == s
