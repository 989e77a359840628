"""Where arsim's bundled assets (environment maps, meshes, textures, tag images) live."""

from __future__ import annotations

import os
from pathlib import Path


def assets_dir() -> Path:
    """The assets folder: $ARSIM_ASSETS if set, else assets/ beside the arsim package (a checkout)."""
    override = os.environ.get("ARSIM_ASSETS")
    if override:
        return Path(override).expanduser().resolve()
    return Path(__file__).resolve().parents[2] / "assets"
