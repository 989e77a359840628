"""`arsim bases compare`: how well each basis of irradiance normal mapping holds directional irradiance
(the integrated squared error over random signals, a table and a bar plot), and a visual comparison like
the spec's figures 3.3/3.4 (a normal-mapped plane under one environment with a sun at a grazing angle, a
tile per basis).

The random signals (drawn by `random_signal`, seed s + k for the k-th): radiance over the upper
hemisphere of a surface, which is what a texel of a directional light map sees, made of
- a sky: a exp(kappa (w . r - 1)) + b, r uniform on the sphere, kappa ~ U(0, 10), a ~ U(0, 1), b ~ U(0, 0.3);
- 0, 1 or 2 suns (equally likely): directions uniform in solid angle over the upper hemisphere (grazing
  ones included), irradiance at normal incidence ~ U(0, 3);
- with probability 1/2 an occluder (a wall, a neighbouring object): the directions within alpha ~ U(20,
  70) degrees of o are black for sky and suns, o at an elevation ~ U(0, 30) degrees, azimuth uniform.
E(n) is integrated for every normal of the evaluation rule (the sky over a 64 x 128 Gauss rule, the suns
exactly). Each basis fits E by least squares over the hemisphere (the best it can hold); its error is
int (E - E~)^2 dn / int E^2 dn over the hemisphere of normals. `sh-rh` is SH as the spec's bake makes it
(radiance projected over the sphere, convolved with the clamped cosine): not a fit to E on the hemisphere.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arsim.core.errors import ArsimError
from arsim.core.files import atomic_path, write_text_atomic
from arsim.lighting.bases.functions import BASES, parse_basis, sh9
from arsim.lighting.bases.irradiance import irradiance, sh9_irradiance_coefficients
from arsim.lighting.bases.projection import project, reconstruct
from arsim.lighting.bases.quadrature import hemisphere_quadrature

COUNTS = (3, 4, 6, 9)
SH_RH = "sh-rh"


@dataclass(frozen=True)
class Signal:
    """Radiance over the upper hemisphere: sky samples (radiance x solid angle) and point lights."""

    directions: np.ndarray  # (K, 3)
    radiance_weighted: np.ndarray  # (K, 1)
    lights: np.ndarray  # (J, 3)
    light_power: np.ndarray  # (J, 1)


def _sky_rule() -> tuple[np.ndarray, np.ndarray]:
    return hemisphere_quadrature(64, 128)


def random_signal(rng: np.random.Generator) -> Signal:
    """One random hemispherical lighting signal, drawn as the module's docstring says."""
    d, w = _sky_rule()
    r = rng.normal(size=3)
    r /= np.linalg.norm(r)
    kappa, a, b = rng.uniform(0, 10), rng.uniform(0, 1), rng.uniform(0, 0.3)
    sky = a * np.exp(kappa * (d @ r - 1)) + b
    count = rng.integers(0, 3)
    z = rng.uniform(0, 1, count)
    phi = rng.uniform(0, 2 * np.pi, count)
    suns = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=-1)
    power = rng.uniform(0, 3, count)
    if rng.uniform() < 0.5:
        elevation, azimuth = np.radians(rng.uniform(0, 30)), rng.uniform(0, 2 * np.pi)
        o = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        cos_alpha = np.cos(np.radians(rng.uniform(20, 70)))
        sky = np.where(d @ o > cos_alpha, 0.0, sky)
        keep = suns @ o <= cos_alpha
        suns, power = suns[keep], power[keep]
    return Signal(d, (sky * w)[:, None], suns.reshape(-1, 3), power.reshape(-1, 1))


def signal_irradiance(signal: Signal, normals: np.ndarray) -> np.ndarray:
    return irradiance(normals, signal.directions, signal.radiance_weighted, signal.lights, signal.light_power)


def fitted(basis_name: str, count: int, signal: Signal, e: np.ndarray, d: np.ndarray, w: np.ndarray,
           at: np.ndarray) -> np.ndarray:
    """E~ at the normals `at` for one basis and count, fitted to E (values e at the rule's directions d,
    weights w; sh-rh: the spec's SH route, from the signal itself)."""
    if basis_name == SH_RH:
        coeffs = sh9_irradiance_coefficients(signal.directions, signal.radiance_weighted, signal.lights, signal.light_power)
        return sh9(at)[..., :count] @ coeffs[:count].reshape((count,) + e.shape[1:])
    basis = BASES[basis_name]
    return reconstruct(basis, count, project(basis, count, e, d, w), at)


def entries() -> list[tuple[str, int]]:
    """Every (basis, count) compared, SH's spec route included."""
    return [(b.name, c) for b in BASES.values() for c in b.counts] + [(SH_RH, 4), (SH_RH, 9)]


def parse_entries(specs: list[str]) -> list[tuple[str, int]]:
    """'h6', 'sh9', 'sh-rh4', 'hl2', ... as (name, count); a bad name or count raises ArsimError."""
    out = []
    for spec in specs:
        if spec.startswith(SH_RH):
            count = spec[len(SH_RH):]
            if count not in ("4", "9"):
                raise ArsimError(f"'{spec}': {SH_RH} has 4 or 9 coefficients ({SH_RH}4, {SH_RH}9)")
            out.append((SH_RH, int(count)))
        else:
            basis, count = parse_basis(spec)
            out.append((basis.name, count))
    return out


@dataclass
class BasesComparison:
    signals: int
    seed: int
    errors: dict[str, list[float]] = field(default_factory=dict)  # "name count" -> per signal relative error

    def summary(self) -> dict[str, dict]:
        return {key: {"mean": float(np.mean(v)), "median": float(np.median(v)), "p95": float(np.percentile(v, 95))}
                for key, v in self.errors.items()}

    def to_json(self) -> dict:
        return {"signals": self.signals, "seed": self.seed, "errors": self.summary()}


def compare_bases(signals: int, seed: int = 0, selected: list[tuple[str, int]] | None = None,
                  progress: Callable[[int], None] = lambda k: None) -> BasesComparison:
    """Each basis and count's (default: all) relative integrated squared error over `signals` random signals."""
    if signals < 1:
        raise ArsimError(f"--signals {signals}: compare over at least 1 signal")
    chosen = selected or entries()
    d, w = hemisphere_quadrature()
    result = BasesComparison(signals, seed, {f"{name} {count}": [] for name, count in chosen})
    for k in range(signals):
        signal = random_signal(np.random.default_rng(seed + k))
        e = signal_irradiance(signal, d)[:, 0]
        norm = float(w @ (e * e))
        for name, count in chosen:
            residual = fitted(name, count, signal, e, d, w, d) - e
            result.errors[f"{name} {count}"].append(float(w @ (residual * residual)) / norm)
        progress(k + 1)
    return result


def _label(key: str) -> str:
    name, count = key.split()
    return f"{'SH, spec route' if name == SH_RH else BASES[name].label} ({count})"


def markdown(c: BasesComparison) -> str:
    s = c.summary()
    lines = ["# Irradiance normal mapping: bases compared", "",
             (f"Relative integrated squared error, int (E - E~)^2 / int E^2 over the hemisphere of normals, over "
              f"{c.signals} random signals (seed {c.seed}; how they are drawn: `arsim/evaluate/compare_bases.py`). "
              "Each basis holds the least-squares fit of E over the hemisphere; `SH, spec route` is SH as the "
              "irradiance-normal-mapping spec bakes it (radiance projected over the sphere, convolved with the "
              "clamped cosine)."), ""]
    for count in COUNTS:
        keys = sorted((k for k in s if int(k.split()[1]) == count), key=lambda k: s[k]["mean"])
        if not keys:
            continue
        lines += [f"## {count} coefficients", "", "| rank | basis | mean | median | p95 |", "|---|---|---|---|---|"]
        lines += [f"| {r + 1} | {_label(k)} | {100 * s[k]['mean']:.3f} % | {100 * s[k]['median']:.3f} % | "
                  f"{100 * s[k]['p95']:.3f} % |" for r, k in enumerate(keys)]
        lines.append("")
    return "\n".join(lines + WHY)


WHY = ["## Why this order", "",
       ("- A least-squares fit over the hemisphere depends only on the span of the functions. SH's first four and "
        "the H-basis's four both span {1, x, y, z}, so they fit alike; the modified H-basis spans what the H-basis "
        "does (H3mod = sqrt(3)/2 H1 - H3/2), so it fits exactly as well, while H1 alone is the light map."),
       ("- Irradiance is a smooth, nearly quadratic function of the normal (the clamped cosine's SH fall off fast "
        "with the band: bands 0-2 hold almost all of it; Ramamoorthi and Hanrahan). So the polynomial bases up to "
        "degree 2 fit best for their counts: H6 adds xy and x^2 - y^2 to {1, x, y, z}; SH9 also has z^2, yz and zx, "
        "three more functions, and fits better still."),
       ("- Half-Life 2's three functions span {x, y, z}: no constant. A uniform sky's irradiance is a constant; "
        "held as a multiple of z it falls to zero at the horizon. Zernike's three hold the constant and gradients "
        "across the surface (x, y over sqrt(1 + z)), but nothing that changes with elevation."),
       ("- The shifted bases (HSH, Makhotkin) map the sphere's pole -z onto the horizon circle: along it every "
        "function is constant (HSH) or zero (Makhotkin, whose functions carry sqrt(z)). With few bands they cannot "
        "vary along the border, and their errors gather at grazing normals (visual_errors.png); Makhotkin's, zero "
        "there, are the worst of their count."),
       ("- SH by the spec's route fits irradiance over the whole sphere of normals, half of which a surface never "
        "shows; fitted over the hemisphere, the same functions do better."),
       ""]


def bar_plot(c: BasesComparison, path: Path) -> None:
    """Mean error per basis, grouped by coefficient count (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = c.summary()
    names = list(BASES) + [SH_RH]
    colours = dict(zip(names, plt.cm.tab10(np.linspace(0, 1, 10))))
    fig, ax = plt.subplots(figsize=(9, 4.5))
    width = 0.8 / len(names)
    for j, name in enumerate(names):
        xs = [i + (j - len(names) / 2) * width for i, count in enumerate(COUNTS) if f"{name} {count}" in s]
        ys = [100 * s[f"{name} {count}"]["mean"] for count in COUNTS if f"{name} {count}" in s]
        label = "SH, spec route" if name == SH_RH else BASES[name].label
        ax.bar(xs, ys, width, color=colours[name], label=label, align="edge")
    ax.set_xticks(range(len(COUNTS)), [f"{n} coefficients" for n in COUNTS])
    ax.set_yscale("log")
    ax.set_ylabel("mean relative integrated squared error (%)")
    ax.set_title(f"Directional irradiance in each basis, {c.signals} random signals", fontsize=10)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def write_bases_comparison(c: BasesComparison, out_dir: Path) -> list[Path]:
    paths = [out_dir / "bases.md", out_dir / "bases.json", out_dir / "bases.png"]
    write_text_atomic(paths[0], markdown(c))
    write_text_atomic(paths[1], json.dumps(c.to_json(), indent=2) + "\n")
    bar_plot(c, paths[2])
    return paths


# --------------------------------------------------------------------------------------------------
# The visual comparison (the spec's figures 3.3/3.4)


def domes_normal_map(size: int, domes: int = 3) -> np.ndarray:
    """(size, size, 3) tangent-space normals of a plane studded with hemispherical domes: each dome shows
    every normal of the hemisphere, its rim the grazing ones where the shifted bases go wrong."""
    centre = (np.arange(size) + 0.5) / size * domes
    v, u = np.meshgrid(centre, centre, indexing="ij")
    du, dv = u - np.floor(u) - 0.5, -(v - np.floor(v) - 0.5)  # (rows run down: the bitangent is up)
    radius = 0.45
    rho2 = (du * du + dv * dv) / (radius * radius)
    inside = rho2 < 1.0
    n = np.zeros((size, size, 3))
    n[..., 2] = 1.0
    n[inside, 0], n[inside, 1] = du[inside] / radius, dv[inside] / radius
    n[inside, 2] = np.sqrt(1.0 - rho2[inside])
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def plane_lighting(env_equirect: np.ndarray, sun_elevation_deg: float, sun_azimuth_deg: float,
                   sun_share: float) -> Signal:
    """A horizontal plane's hemispherical lighting in its tangent space (x = world x, y = world -z, z =
    world up) from an equirect environment (radiance samples at its texels), plus a sun at the given
    elevation whose irradiance at normal incidence is sun_share times the sky's on the flat plane."""
    from arsim.core.conventions import equirect_directions, equirect_solid_angles

    h = env_equirect.shape[0]
    world = equirect_directions(h).reshape(-1, 3)
    tangent = np.stack([world[:, 0], -world[:, 2], world[:, 1]], axis=-1)
    weighted = env_equirect[..., :3].reshape(-1, 3).astype(np.float64) * equirect_solid_angles(h).reshape(-1, 1)
    sky_flat = irradiance(np.array([[0.0, 0.0, 1.0]]), tangent, weighted)[0]
    e, a = np.radians(sun_elevation_deg), np.radians(sun_azimuth_deg)
    sun = np.array([[np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)]])
    return Signal(tangent, weighted, sun, sun_share * sky_flat.mean() * np.ones((1, 3)))


@dataclass
class VisualComparison:
    reference: np.ndarray  # (S, S, 3) irradiance per pixel
    tiles: dict[str, np.ndarray]  # "name count" -> (S, S, 3)

    def errors(self) -> dict[str, float]:
        """Per tile: relative squared error over the pixels."""
        norm = float((self.reference ** 2).sum())
        return {key: float(((tile - self.reference) ** 2).sum()) / norm for key, tile in self.tiles.items()}


def visual_comparison(signal: Signal, size: int = 192, domes: int = 3,
                      selected: list[tuple[str, int]] | None = None) -> VisualComparison:
    """The domed plane's irradiance per pixel: exact, and through each basis (fitted to the texel's E
    over the hemisphere, then evaluated with each pixel's normal)."""
    normals = domes_normal_map(size, domes)
    reference = signal_irradiance(signal, normals)
    d, w = hemisphere_quadrature()
    e = signal_irradiance(signal, d)  # (K, 3)
    tiles = {f"{name} {count}": fitted(name, count, signal, e, d, w, normals) for name, count in selected or entries()}
    return VisualComparison(reference, tiles)


ERROR_SHOWN_MAX = 0.25  # visual_errors.png's colour scale: |E~ - E| / max E from 0 to this (beyond: the top colour)


def visual_figure(v: VisualComparison, kind: str, title: str):
    """kind "tiles": the tiles' irradiance on one shared exposure (sRGB), with a colour bar of that scale;
    "errors": their error maps |E~ - E| / max E, with a colour bar in percent."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize, PowerNorm

    scale = float(np.percentile(v.reference, 99.5))
    errors = v.errors()
    keys = ["reference"] + list(v.tiles)
    columns = 6
    rows = -(-len(keys) // columns)
    peak = float(v.reference.max())
    fig, axes = plt.subplots(rows, columns, figsize=(2.0 * columns + 1.0, 2.15 * rows + 0.3), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, key in zip(axes.flat, keys):
        image = v.reference if key == "reference" else v.tiles[key]
        if kind == "tiles":
            ax.imshow(np.clip(np.maximum(image, 0.0) / scale, 0, 1) ** (1 / 2.2))
        else:
            ax.imshow(100 * np.abs(image - v.reference).mean(axis=-1) / peak, cmap="magma", vmin=0,
                      vmax=100 * ERROR_SHOWN_MAX)
        if key == "reference":
            ax.set_title("reference (exact)" + ("" if kind == "tiles" else "\nno error"), fontsize=7)
        else:
            ax.set_title(f"{_label(key)}\n{100 * errors[key]:.2f} %", fontsize=7)
    if kind == "tiles":  # every tile on the reference's exposure: a grey ramp stands for each channel's scale
        shown = ScalarMappable(PowerNorm(1 / 2.2, vmin=0.0, vmax=scale), cmap="gray")
        label = "irradiance E per channel\n(the map's radiance units x sr, gamma 2.2)"
        suffix = ": irradiance per pixel, one exposure; above each tile its relative squared error"
    else:
        shown = ScalarMappable(Normalize(0.0, 100 * ERROR_SHOWN_MAX), cmap="magma")
        label = "|E~ - E| / max E (%), mean of the channels"
        suffix = ": error per pixel; above each tile its relative squared error"
    fig.colorbar(shown, ax=axes.ravel().tolist(), fraction=0.02, pad=0.02, label=label,
                 extend="neither" if kind == "tiles" else "max")
    fig.suptitle(title + suffix, fontsize=9)
    return fig


def visual_figures(v: VisualComparison, path_tiles: Path, path_errors: Path, title: str) -> None:
    """visual.png (the tiles) and visual_errors.png (their error maps), each with its colour bar."""
    import matplotlib.pyplot as plt

    for path, kind in ((path_tiles, "tiles"), (path_errors, "errors")):
        fig = visual_figure(v, kind, title)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=100, bbox_inches="tight")
        plt.close(fig)


@dataclass(frozen=True)
class BasesStudy:
    """`arsim bases compare`'s results: each basis's mean error over random signals and on the visual
    comparison's plane, and the files written."""

    errors: dict[str, dict]  # "name count" -> the random signals' statistics (BasesComparison.summary)
    visual_errors: dict[str, float]  # "name count" -> relative squared error on the plane
    paths: list[Path]


def visual_environment(path: Path | None = None) -> tuple[np.ndarray, str]:
    """The visual comparison's environment (default: the assets' interior.exr) as a 32-row equirect, and its
    name; a file that cannot be read, or holds NaN/Inf texels, is refused."""
    from arsim.core.assets import assets_dir
    from arsim.core.hdr_io import read_hdr, replace_nonfinite
    from arsim.core.resample import to_layout

    path = path or assets_dir() / "envmaps" / "interior.exr"
    env, _ = replace_nonfinite(read_hdr(path), "refuse", str(path))
    return to_layout(env, "equirect", 32), Path(path).name  # (irradiance is smooth: 32 x 64 samples hold it)


def bases_study(out_dir: Path, signals: int, seed: int = 0, selected: list[tuple[str, int]] | None = None,
                environment: tuple[np.ndarray, str] | None = None, sun_elevation_deg: float = 8.0,
                sun_share: float = 3.0, progress: Callable[[int], None] = lambda k: None) -> BasesStudy:
    """The comparison over random signals (bases.md, bases.json, bases.png) and the visual comparison
    under `environment` (visual_environment's; default: the assets' interior.exr) with a sun at
    sun_elevation_deg (visual.png, visual_errors.png), written into out_dir."""
    if not 0.0 <= sun_elevation_deg <= 90.0:
        raise ArsimError(f"sun elevation {sun_elevation_deg:g} is not an elevation: give 0 to 90 degrees")
    env, name = environment or visual_environment()
    comparison = compare_bases(signals, seed, selected, progress=progress)
    paths = write_bases_comparison(comparison, out_dir)
    visual = visual_comparison(plane_lighting(env, sun_elevation_deg, 30.0, sun_share), selected=selected)
    paths += [out_dir / "visual.png", out_dir / "visual_errors.png"]
    visual_figures(visual, paths[-2], paths[-1], f"{name}, sun at {sun_elevation_deg:g} degrees elevation")
    return BasesStudy(comparison.summary(), visual.errors(), paths)
