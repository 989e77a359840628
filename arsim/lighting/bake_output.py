"""A bake on disk (README: Irradiance and reflection maps): irradiance.exr, reflection_s<S>.exr and bake.json in one folder."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from arsim.core.errors import ArsimError
from arsim.core.files import write_text_atomic
from arsim.core.hdr_io import read_hdr, write_exr
from arsim.lighting.mapset import MapSet
from arsim.lighting.methods import BakeResult, MapParameters, parameters_used


def map_filename(exponent: float) -> str:
    """irradiance.exr for s = 1, reflection_s<S>.exr otherwise (S without a trailing .0)."""
    if exponent == 1:
        return "irradiance.exr"
    return f"reflection_s{int(exponent) if float(exponent).is_integer() else f'{exponent:g}'}.exr"


def write_bake(out_dir: Path, exponents: Sequence[float], method: str, params: MapParameters,
               result: BakeResult, source: str) -> list[Path]:
    """Write every map (atomically) and bake.json with method, parameters and timings; returns the paths."""
    files, paths = {}, []
    for s, image, seconds in zip(exponents, result.maps, result.seconds_per_map):
        name = map_filename(s)
        write_exr(out_dir / name, image)
        files[name] = {"exponent": float(s), "seconds": round(seconds, 4)}
        paths.append(out_dir / name)
    record = {
        "method": method,
        "parameters": parameters_used(method, params),
        "environment": source,
        "size": int(result.maps.shape[1]),
        "computed_on": result.computed_on,
        "summed_over": result.summed_over,
        "maps": files,
        "seconds_shared": round(result.seconds_shared, 4),
        "seconds_total": round(result.seconds_total, 4),
    }
    write_text_atomic(out_dir / "bake.json", json.dumps(record, indent=2) + "\n")
    return paths + [out_dir / "bake.json"]


def read_bake(folder: Path) -> MapSet:
    """A bake folder written by write_bake, as its map set; ArsimError where the folder is not one, or a map
    it lists is missing or of another size."""
    record_path = folder / "bake.json"
    if not record_path.is_file():
        raise ArsimError(f"{folder}: no bake.json here; give a folder written by `arsim bake`")
    try:
        record = json.loads(record_path.read_text(encoding="utf-8"))
        method, files = str(record["method"]), record["maps"]
        exponents = {name: float(entry["exponent"]) for name, entry in files.items()}
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ArsimError(f"{record_path}: not a bake record ({type(exc).__name__}: {exc}); bake the maps again with `arsim bake`") from None
    maps = {}
    for name, exponent in exponents.items():
        image = read_hdr(folder / name)  # a missing or broken file raises its own one-line ArsimError
        if image.shape[:2] != (image.shape[0], image.shape[0]) or (maps and image.shape != next(iter(maps.values())).shape):
            raise ArsimError(f"{folder / name}: a {image.shape[1]} x {image.shape[0]} map among others; a bake's maps are one size")
        maps[exponent] = image.astype(np.float32)
    return MapSet(method, maps, str(folder))
