"""Scenario files: TOML parsed into frozen, checked dataclasses (see sections.py for the keys)."""

from arsim.scenario.loader import DEFAULT_SCENARIO, load_scenario, scenario_to_toml
from arsim.scenario.schema import ScenarioError
from arsim.scenario.sections import EnvironmentSection, RunSection, Scenario

__all__ = [
    "DEFAULT_SCENARIO",
    "EnvironmentSection",
    "RunSection",
    "Scenario",
    "ScenarioError",
    "load_scenario",
    "scenario_to_toml",
]
