"""Maps for engines (README: Maps for engines): a light probe, or a bake folder with the probe it was baked from,
written in the forms engines load: KTX2 cube maps (the GGX chain of the split sum, the radiance, the thesis's
Phong maps, the irradiance map) and the split sum's BRDF table; Filament's sh.txt and the SH as JSON; a glTF
scene with EXT_lights_image_based and three spheres; cube faces and equirects as image files.

Conventions: directions are arsim's world axes (right-handed, +y up: those of Filament and glTF too); a cube
map's texel that a GL or Vulkan sampler reads for direction d holds the light from d (OpenGL's cube-map
convention, core.conventions.CUBE_FACES), so nothing is mirrored.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from arsim.core.assets import assets_dir
from arsim.core.conventions import CUBE_FACE_SUFFIXES
from arsim.core.errors import ArsimError
from arsim.core.files import atomic_path, json_text, write_text_atomic
from arsim.core.hdr_io import read_hdr, replace_nonfinite, write_image
from arsim.core.ktx2 import write_ktx2
from arsim.core.resample import detect_layout, to_cube, to_layout
from arsim.lighting.bake_output import map_filename, read_bake
from arsim.lighting.bases.projection import sh_radiance
from arsim.lighting.ggx import brdf_lut, level_roughness, prefilter_ggx
from arsim.lighting.gltf_ibl import write_ibl_scene
from arsim.lighting.mapset import MapSet

MAP_FORMATS = {
    "ktx2": "KTX2 cube maps: specular_ggx.ktx2 (the GGX chain), skybox.ktx2 (the radiance), brdf_lut.ktx2 and .png "
            "(the split sum's table); from a bake also phong.ktx2 (its maps, one level each) and irradiance.ktx2",
    "filament": "Filament's sh.txt (pre-scaled, as cmgen writes it) and sh.json (the radiance's 27 SH coefficients)",
    "gltf": "gltf/ibl.gltf with EXT_lights_image_based (RGBD PNG faces per GGX level, irradiance SH) and three spheres",
    "faces": "faces/<map>_px ... _nz: the six cube faces of the radiance (and of a bake's maps) as image files",
    "equirect": "equirect/<map>: the radiance (and a bake's maps) as equirects",
}
IMAGE_SUFFIXES = (".exr", ".hdr", ".png")
IRRADIANCE_FACE = 32  # the irradiance map's cube: smooth, 32 x 32 per face is plenty
MIN_FACE, MAX_FACE = 16, 2048

# Band factors of the clamped cosine (Ramamoorthi and Hanrahan 2001): E_lm = A_l L_lm
BAND_FACTORS = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)
# The real SH basis's constants per coefficient, the factors of its polynomials (bases.functions.sh9):
# Y_00 = K0, Y_1-1 = K1 y, Y_10 = K1 z, Y_11 = K1 x, Y_2-2 = K2 xy, Y_2-1 = K2 yz, Y_20 = K3 (3z^2 - 1), Y_21 = K2 zx,
# Y_22 = K4 (x^2 - y^2)
_K0, _K1, _K2, _K3 = 0.5 / np.sqrt(np.pi), 0.5 * np.sqrt(3 / np.pi), 0.5 * np.sqrt(15 / np.pi), 0.25 * np.sqrt(5 / np.pi)
BASIS_CONSTANTS = np.array([_K0, _K1, _K1, _K1, _K2, _K2, _K3, _K2, 0.5 * _K2])
SH_ORDER = ("(0,0)", "(1,-1)", "(1,0)", "(1,1)", "(2,-2)", "(2,-1)", "(2,0)", "(2,1)", "(2,2)")
_FILAMENT_NAMES = ("L00", "L1-1", "L10", "L11", "L2-2", "L2-1", "L20", "L21", "L22")


@dataclass
class ExportSource:
    """What an export reads: the radiance as an angle map (None where a bake's environment is not found, with
    why), and a bake's maps (None for a probe)."""

    name: str
    radiance: np.ndarray | None
    maps: MapSet | None = None
    missing: str = ""


@dataclass
class ExportResult:
    files: list[Path] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)


def check_formats(formats: Sequence[str]) -> list[str]:
    """The formats asked for, each once, in the order given; ArsimError for an unknown one."""
    out = []
    for name in formats:
        name = name.strip().lower()
        if name not in MAP_FORMATS:
            raise ArsimError(f"export format {name!r} is unknown; the maps' formats are {', '.join(MAP_FORMATS)}")
        if name not in out:
            out.append(name)
    if not out:
        raise ArsimError(f"no export format given; give --format with one or more of {', '.join(MAP_FORMATS)}")
    return out


def _probe(path: Path) -> np.ndarray:
    """An HDR image as an angle map (at its height): refused in one line where it is not HDR or holds NaN/Inf."""
    image, _ = replace_nonfinite(read_hdr(path), "refuse", str(path), fix="replace them with `arsim convert IN OUT --nan zero`")
    detect_layout(image, str(path))
    return to_layout(image, "anglemap")


def _bake_environment(folder: Path) -> tuple[Path | None, str]:
    """The probe a bake was made from, as its bake.json names it: found as given (from here), beside the bake
    and above it (a run's maps/<method>/ names capture/env.exr), or among the bundled assets."""
    try:
        named = json.loads((folder / "bake.json").read_text(encoding="utf-8"))["environment"]
    except (KeyError, TypeError, ValueError):
        named = None
    if not isinstance(named, str) or not named or "\x00" in named:
        return None, f"{folder / 'bake.json'} names no environment"
    named_path = Path(named)
    candidates = [named_path, folder / named_path] + [parent / named_path for parent in folder.resolve().parents[:2]]
    bundled = named_path.parts[1:] if named_path.parts[:1] == ("assets",) else named_path.parts  # assets/envmaps/x.exr
    candidates.append(assets_dir().joinpath(*bundled))
    for candidate in candidates:
        if candidate.is_file():
            return candidate, ""
    return None, f"{folder / 'bake.json'} names its environment {named}, which is not found from here"


def load_source(path: Path, env: Path | None = None) -> ExportSource:
    """A bake folder (its maps, and the probe it names or `env`) or an HDR probe (an angle map or an equirect)."""
    if path.is_dir():
        maps = read_bake(path)  # a folder that is not a bake, or one missing a map, is refused here
        found, why = (env, "") if env is not None else _bake_environment(path)
        return ExportSource(str(path), _probe(found) if found is not None else None, maps, why)
    if env is not None:
        raise ArsimError(f"--env is for a bake folder; {path} is itself the probe")
    return ExportSource(str(path), _probe(path))


def check_face_size(size: int | None) -> None:
    """ArsimError unless the cube faces' side asked for (None: the default) is a power of two, MIN_FACE to MAX_FACE."""
    if size is not None and (size & (size - 1) or not MIN_FACE <= size <= MAX_FACE):
        raise ArsimError(f"face size {size} is not allowed: give a power of two from {MIN_FACE} to {MAX_FACE}")


RADIANCE_FORMATS = ("ktx2", "gltf", "faces", "equirect")  # those that need the radiance, not only a bake's maps


def check_source(source: ExportSource, formats: Sequence[str]) -> None:
    """ArsimError, before any output, where a format needs what the source lacks: the radiance of a bake whose
    probe is not found (all but filament), for filament the radiance or else an irradiance map."""
    needing = [f for f in formats if f in RADIANCE_FORMATS]
    if source.radiance is None and needing:
        verb = "needs" if len(needing) == 1 else "need"
        raise ArsimError(f"{', '.join(needing)} {verb} the radiance, and {source.missing}; pass --env PROBE (the probe "
                         "the maps were baked from)")
    if "filament" in formats:
        sh_origin(source)


def face_size(source: ExportSource, size: int | None) -> int:
    """The cube faces' side: as given, or the power of two nearest a quarter of the angle map's side (a
    face's central texel then spans about what the angle map's central texel does), MIN_FACE to MAX_FACE."""
    check_face_size(size)
    if size is not None:
        return size
    n = source.radiance.shape[0] if source.radiance is not None else source.maps.size
    return int(np.clip(2 ** round(np.log2(n / 4)), MIN_FACE, MAX_FACE))


# ---------------------------------------------------------------------------------------------------
# Spherical harmonics


def sh_origin(source: ExportSource) -> str:
    """Where the SH come from: the radiance, or a bake's irradiance map where its probe is not found; ArsimError
    where neither is there."""
    if source.radiance is not None:
        return "the radiance"
    if source.maps is not None and 1.0 in source.maps:
        return "the bake's irradiance map"
    raise ArsimError(f"{source.name}: has no irradiance map (exponent 1) and {source.missing}; pass --env PROBE")


def sh_of(source: ExportSource) -> tuple[np.ndarray, str]:
    """(9, 3) the radiance's SH L_lm (lighting.bases.projection.sh_radiance's basis and order) and where they
    came from: the radiance, or a bake's irradiance map (E / pi, whose bands 0-2 are A_l L_lm / pi exactly,
    since a convolution with the cosine lobe acts band by band)."""
    origin = sh_origin(source)
    if source.radiance is not None:
        return sh_radiance(source.radiance), origin
    return sh_radiance(source.maps[1.0]) * (np.pi / BAND_FACTORS)[:, None], origin


def filament_sh(sh: np.ndarray) -> np.ndarray:
    """(9, 3) Filament's pre-scaled irradiance SH (what cmgen writes to sh.txt): L_lm A_l / pi times the basis
    constant, so that Filament's shader, sum sh[i] * polynomial_i(n) with the polynomials 1, y, z, x, yx, yz,
    3z^2 - 1, zx, x^2 - y^2, gives E(n) / pi, the irradiance over pi (Lambert's diffuse without the albedo).
    cmgen's basis carries the Condon-Shortley phase and its constants the same signs, which cancel: in arsim's
    basis (no phase) every factor is positive."""
    return np.asarray(sh, dtype=np.float64) * (BAND_FACTORS / np.pi * BASIS_CONSTANTS)[:, None]


def _write_filament(out: Path, sh: np.ndarray, origin: str) -> list[Path]:
    pre = filament_sh(sh)
    lines = [f"({r: .9f}, {g: .9f}, {b: .9f}); // {name}, irradiance, pre-scaled base"
             for (r, g, b), name in zip(pre, _FILAMENT_NAMES)]
    write_text_atomic(out / "sh.txt", "\n".join(lines) + "\n")
    record = {
        "convention": "radiance L_lm in the real orthonormal SH basis without the Condon-Shortley phase "
                      "(Y_1-1 = K1 y, Y_10 = K1 z, Y_11 = K1 x, ...), of arsim's world direction: right-handed, +y up; "
                      "the irradiance is E(n) = sum A_l L_lm Y_lm(n), A_l = pi, 2 pi / 3, pi / 4",
        "order": list(SH_ORDER),
        "from": origin,
        "coefficients": sh.tolist(),
    }
    write_text_atomic(out / "sh.json", json_text(record))
    return [out / "sh.txt", out / "sh.json"]


# ---------------------------------------------------------------------------------------------------
# Images


def write_lut_png(path: Path, lut: np.ndarray) -> None:
    """The split sum's table as a 16-bit PNG: red the scale, green the bias, blue 0; row 0 (the top) roughness
    near 0."""
    rgb16 = np.round(np.clip(np.concatenate([lut, np.zeros(lut.shape[:2] + (1,))], axis=-1), 0.0, 1.0) * 65535).astype(np.uint16)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(rgb16[..., ::-1])):
            raise ArsimError(f"{path}: could not be written as PNG")


# ---------------------------------------------------------------------------------------------------
# The export


class _Cache:
    """What several formats share, computed once: the radiance's cube and GGX chain, the maps' cubes."""

    def __init__(self, source: ExportSource, size: int):
        self.source, self.size = source, size
        self._cube = self._chain = self._lut = None

    def radiance(self, why: str) -> np.ndarray:
        check_source(self.source, [why])
        return self.source.radiance

    def cube(self, why: str) -> np.ndarray:
        if self._cube is None:
            self._cube = to_cube(self.radiance(why), self.size)
        return self._cube

    def chain(self, why: str) -> list[np.ndarray]:
        if self._chain is None:
            self._chain = prefilter_ggx(self.cube(why))
        return self._chain

    def lut(self) -> np.ndarray:
        if self._lut is None:
            self._lut = brdf_lut()
        return self._lut


def _map_names(maps: MapSet) -> list[tuple[float, str]]:
    return [(s, Path(map_filename(s)).stem) for s in maps.exponents]


def _phong_levels(maps: MapSet, size: int) -> tuple[list[np.ndarray], list[float]]:
    """A bake's maps as one mip chain, the largest exponent (the sharpest) at level 0: level p is N >> p per
    face with N the larger of the face size and 2^(maps - 1), so that every map has a level."""
    exponents = sorted(maps.exponents, reverse=True)
    base = max(size, 2 ** (len(exponents) - 1))
    return [to_cube(maps[s], max(1, base >> p)) for p, s in enumerate(exponents)], exponents


def _ktx2(cache: _Cache, out: Path, texel: str) -> list[Path]:
    chain = cache.chain("ktx2")
    roughness = " ".join(f"{r:g}" for r in level_roughness(len(chain)))
    files = []
    write_ktx2(out / "specular_ggx.ktx2", chain, texel, {"arsim.roughness": roughness,
                                                         "arsim.content": "GGX-prefiltered radiance (split sum), n = v = r"})
    write_ktx2(out / "skybox.ktx2", [cache.cube("ktx2")], texel, {"arsim.content": "radiance"})
    lut = cache.lut()
    write_ktx2(out / "brdf_lut.ktx2", [lut[None]], "rg16f",
               {"arsim.content": "split-sum BRDF table: red scale, green bias; column n.v, row perceptual roughness"})
    write_lut_png(out / "brdf_lut.png", lut)
    files += [out / n for n in ("specular_ggx.ktx2", "skybox.ktx2", "brdf_lut.ktx2", "brdf_lut.png")]
    maps = cache.source.maps
    if maps is not None:
        levels, exponents = _phong_levels(maps, cache.size)
        write_ktx2(out / "phong.ktx2", levels, texel, {
            "arsim.phongExponents": " ".join(f"{s:g}" for s in exponents),
            "arsim.content": "normalised Phong-lobe averages of the radiance (exponent 1: irradiance / pi), one level per exponent"})
        files.append(out / "phong.ktx2")
        if 1.0 in maps:
            write_ktx2(out / "irradiance.ktx2", [to_cube(maps[1.0], IRRADIANCE_FACE)], texel,
                       {"arsim.content": "irradiance / pi (the bake's map for exponent 1)"})
            files.append(out / "irradiance.ktx2")
    return files


def _images(cache: _Cache, out: Path, kind: str, suffix: str) -> list[Path]:
    folder = out / kind
    folder.mkdir(exist_ok=True)
    items = [("radiance", cache.radiance(kind))]
    if cache.source.maps is not None:
        items += [(stem, cache.source.maps[s]) for s, stem in _map_names(cache.source.maps)]
    files = []
    for stem, anglemap in items:
        if kind == "faces":
            cube = cache.cube(kind) if stem == "radiance" else to_cube(anglemap, cache.size)
            for face, tag in zip(cube, CUBE_FACE_SUFFIXES):
                write_image(folder / f"{stem}_{tag}{suffix}", face)
                files.append(folder / f"{stem}_{tag}{suffix}")
        else:
            write_image(folder / f"{stem}{suffix}", to_layout(anglemap, "equirect", 2 * cache.size))
            files.append(folder / f"{stem}{suffix}")
    return files


def export_maps(source: ExportSource, formats: Sequence[str], out: Path, size: int | None = None,
                image_suffix: str = ".exr", texel: str = "rgba16f",
                progress: Callable[[str], None] | None = None) -> ExportResult:
    """Write every format asked for into the folder `out` (README: Maps for engines); the seconds each took."""
    formats = check_formats(formats)
    check_source(source, formats)
    if image_suffix not in IMAGE_SUFFIXES:
        raise ArsimError(f"image type {image_suffix!r} is unknown; use one of {', '.join(IMAGE_SUFFIXES)}")
    if texel not in ("rgba16f", "b10g11r11"):
        raise ArsimError(f"KTX2 texel format {texel!r} is unknown; use rgba16f or b10g11r11")
    cache = _Cache(source, face_size(source, size))
    result = ExportResult()
    for name in formats:
        if progress is not None:
            progress(name)
        start = time.perf_counter()
        if name == "ktx2":
            result.files += _ktx2(cache, out, texel)
        elif name == "filament":
            result.files += _write_filament(out, *sh_of(source))
        elif name == "gltf":
            sh, _ = sh_of(source)
            result.files += write_ibl_scene(out / "gltf", cache.chain("gltf"), sh * BAND_FACTORS[:, None])
        else:
            result.files += _images(cache, out, name, image_suffix)
        result.seconds[name] = time.perf_counter() - start
    return result


