"""Where arsim's bundled data live: the assets (environment maps, meshes) and the example scenarios.

Both are package data under arsim/data/, so a checkout, an editable install and a wheel find them the same
way; a checkout also has assets/ and scenarios/ at its root as links to them, for the README's examples.
"""

from __future__ import annotations

import os
from pathlib import Path

_DATA = Path(__file__).resolve().parents[1] / "data"


def assets_dir() -> Path:
    """The assets folder: $ARSIM_ASSETS if set, else the one bundled with the package."""
    override = os.environ.get("ARSIM_ASSETS")
    if override:
        return Path(override).expanduser().resolve()
    return _DATA / "assets"


def scenarios_dir() -> Path:
    """The folder of the bundled example scenarios (indoor, night, lost_tag, ...)."""
    return _DATA / "scenarios"


def bundled_scenarios() -> dict[str, Path]:
    """The bundled scenarios by name (the file's stem), sorted."""
    return {p.stem: p for p in sorted(scenarios_dir().glob("*.toml"))}
