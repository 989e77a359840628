"""Loading scenario files (or the embedded default) into a checked Scenario."""

from __future__ import annotations

import os
import tomllib
from importlib import resources
from pathlib import Path

import tomli_w

from arsim.core.assets import assets_dir, bundled_scenarios
from arsim.scenario.schema import PathResolver, ScenarioError, parse_section, section_to_dict
from arsim.scenario.sections import Scenario

__all__ = ["DEFAULT_SCENARIO", "load_scenario", "parse_scenario", "scenario_path", "scenario_to_toml"]

# Shown in messages and manifests where the embedded default scenario is meant.
DEFAULT_SCENARIO = "<default scenario>"


def _default_text() -> str:
    return resources.files("arsim.scenario").joinpath("default.toml").read_text(encoding="utf-8")


def parse_scenario(text: str, source: str = DEFAULT_SCENARIO, scenario_dir: Path | None = None) -> Scenario:
    """A Scenario from TOML text; paths resolve against scenario_dir, then against the assets."""
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: is not valid TOML ({exc}); fix the syntax at that place") from None
    return parse_section(Scenario, table, source, PathResolver(scenario_dir, assets_dir()))


def scenario_path(path: str | os.PathLike) -> Path:
    """The scenario file that path names: the path itself, or where no such file exists and path is a bare
    name (no folder, no suffix), the bundled scenario of that name (`arsim run indoor`)."""
    path = Path(path)
    if path.is_file() or path.suffix or len(path.parts) != 1:
        return path  # (a bare name that is a folder, such as the output of `arsim run quick -o quick`, is not a scenario)
    return bundled_scenarios().get(path.name, path)


def load_scenario(path: str | os.PathLike | None = None) -> Scenario:
    """The scenario in the TOML file at path (or a bundled scenario's name), or the embedded default when
    path is None."""
    if path is None:
        return parse_scenario(_default_text())
    path = scenario_path(path)
    if not path.exists():
        names = ", ".join(bundled_scenarios())
        raise ScenarioError(f"{path}: no such scenario file; check the path, name a bundled scenario ({names}) "
                            "or leave it out to use the default scenario")
    if not path.is_file():
        raise ScenarioError(f"{path}: is not a file; give a scenario .toml file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ScenarioError(f"{path}: is not a text file; give a scenario .toml file") from None
    return parse_scenario(text, str(path), path.resolve().parent)


def scenario_to_toml(scenario: Scenario, portable: bool = False) -> str:
    """The scenario as resolved (defaults filled in, paths absolute), as TOML text. portable: the paths to the
    bundled assets written relative to them (as a scenario names them, "envmaps/interior.exr"), so that what
    keeps the text (a recording's meta.json) still loads where arsim is installed elsewhere."""
    table = section_to_dict(scenario)
    if portable:
        table = _relative_to(table, str(assets_dir().resolve()) + os.sep)
    return tomli_w.dumps(table)


def _relative_to(value, prefix: str):
    """value (a TOML-ready dict, list or scalar) with every string that starts with prefix (a folder, with
    its separator) cut to the rest."""
    if isinstance(value, dict):
        return {k: _relative_to(v, prefix) for k, v in value.items()}
    if isinstance(value, list):
        return [_relative_to(v, prefix) for v in value]
    return value[len(prefix):] if isinstance(value, str) and value.startswith(prefix) else value
