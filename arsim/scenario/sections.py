"""The sections of a scenario file. Adding a section: write its dataclass here, add it to Scenario."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from arsim.scenario.schema import setting, subsection


@dataclass(frozen=True)
class RunSection:
    """[run]: what the run is called and the seed every random stream derives from."""

    name: str = setting("default", help="name of the run, used in reports and file names")
    seed: int = setting(0, min=0, max=2**32 - 1, help="seed of every random stream of the run")


@dataclass(frozen=True)
class EnvironmentSection:
    """[environment]: the true HDR environment around the scene (the ground truth of the light)."""

    map: Path = setting(
        Path("envmaps/interior.exr"),
        must_exist=True,
        help="HDR environment (.exr or .hdr, equirect 2:1 or angle map 1:1); relative to the scenario, then to assets/",
    )
    probe_size: int = setting(512, min=16, max=4096, unit="texels", help="N of the N x N angle map the environment is held in")
    intensity: float = setting(1.0, min=0.0, max=1e6, help="factor applied to the environment's radiance")
    yaw_deg: float = setting(0.0, min=-360.0, max=360.0, unit="degrees", help="rotation of the environment about world +y")


@dataclass(frozen=True)
class Scenario:
    """A whole scenario: one field per TOML section, each a checked, frozen dataclass."""

    run: RunSection = subsection(RunSection, help="run name and seed")
    environment: EnvironmentSection = subsection(EnvironmentSection, help="the true HDR environment")
