"""A normal-mapped torus on the table, three ways (irradiance normal mapping against the thesis):
- reference: per pixel, the irradiance integrated over the surface's hemisphere with the perturbed
  normal and the visibility (rays sphere-traced against the torus and the table);
- INM: the torus's directional light map in a basis (the modified H-basis by default), looked up at
  the pixel's light-map texel and evaluated with the normal map's tangent-space normal;
- thesis: the irradiance map looked up with the perturbed normal, times the ambient-occlusion light map
  (Alg. 5.2 with 5.4).
The view is ray-cast in NumPy (the torus's exact distance function), so the comparison needs no GL: it
is the oracle a GL path of the same materials is held to. Diffuse only, white albedo: radiance E / pi.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arsim.core.conventions import normalize
from arsim.core.resample import sample_anglemap, to_layout
from arsim.lighting.accurate import accurate_maps
from arsim.lighting.bases.functions import Basis
from arsim.lighting.bases.lightmap import Surface, bake_directional, decode_8bit, encode_8bit, probe_samples
from arsim.render.content import (
    bake_torus_occlusion,
    ridges_normal_map,
    scene_distance,
    sphere_trace,
    torus_distance,
    torus_surface,
    torus_texels,
)
from arsim.render.shading import perturbed_normal

MAJOR, MINOR = 0.05, 0.02


@dataclass(frozen=True)
class TorusView:
    """Per pixel (H, W): whether the torus is hit, and there the point, normal, tangent and (u, v)."""

    hit: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    uv: np.ndarray


def torus_view(width: int, height: int, distance: float = 0.2, elevation_deg: float = 35.0,
               fov_deg: float = 50.0) -> TorusView:
    """The torus seen by a pinhole camera `distance` metres from its centre, looking down at it."""
    e = np.radians(elevation_deg)
    eye = np.array([0.0, MINOR + distance * np.sin(e), distance * np.cos(e)])
    target = np.array([0.0, MINOR, 0.0])
    forward = normalize(target - eye)
    right = normalize(np.cross(forward, [0.0, 1.0, 0.0]))
    up = np.cross(right, forward)
    f = 0.5 * width / np.tan(np.radians(fov_deg) / 2)
    x, y = np.meshgrid(np.arange(width) + 0.5 - width / 2, height / 2 - np.arange(height) - 0.5)
    rays = normalize(forward * f + right * x[..., None] + up * y[..., None])
    travelled = np.zeros((height, width))
    hit = np.zeros((height, width), bool)
    for _ in range(256):
        d = torus_distance(eye + rays * travelled[..., None], MAJOR, MINOR)
        hit |= d < 1e-6
        travelled = np.where(hit, travelled, travelled + d)
        if (hit | (travelled > 4 * distance)).all():
            break
    p = eye + rays * travelled[..., None]
    # The torus's parameters at the hit: u around the ring, v around the tube (torus_surface's).
    u = np.mod(np.arctan2(p[..., 0], p[..., 2]) / (2 * np.pi), 1.0)
    ring = np.stack([np.sin(2 * np.pi * u), np.zeros_like(u), np.cos(2 * np.pi * u)], axis=-1)
    rel = p - ring * MAJOR - np.array([0.0, MINOR, 0.0])
    v = np.mod(np.arctan2(rel[..., 1], np.sum(rel * ring, axis=-1)) / (2 * np.pi), 1.0)
    points, normals, tangents = torus_surface(u, v, MAJOR, MINOR)
    return TorusView(hit, points, normals, tangents, np.stack([u, v], axis=-1))


def sample_periodic(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup of an (H, W, ...) texture, row 0 at v = 1, wrapping in both u and v (the torus)."""
    h, w = texture.shape[:2]
    x = uv[..., 0] * w - 0.5
    y = (1.0 - uv[..., 1]) * h - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    ax, ay = x - x0, y - y0
    extra = (None,) * (texture.ndim - 2)
    ax, ay = ax[(...,) + extra], ay[(...,) + extra]

    def at(r, c):
        return texture[np.mod(r, h), np.mod(c, w)]

    return ((1 - ay) * ((1 - ax) * at(y0, x0) + ax * at(y0, x0 + 1)) + ay * ((1 - ax) * at(y0 + 1, x0) + ax * at(y0 + 1, x0 + 1)))


def _blocked(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Rays (K, T) from points (T, 3) along directions (K, T, 3) that hit the torus or the table."""
    start = origins + directions * (2e-3 * MINOR)
    return sphere_trace(start, directions, lambda p: scene_distance(p, MAJOR, MINOR), MINOR, 6.0 * (MAJOR + MINOR))


@dataclass
class InmComparison:
    reference: np.ndarray  # (H, W, 3) radiance, 0 off the torus
    thesis: np.ndarray
    inm: dict[str, np.ndarray]  # per lighting label ("modh6", "modh6 8-bit")
    hit: np.ndarray


def lighting_label(basis: Basis, count: int, quantise: bool) -> str:
    return f"{basis.name}{count}" + (" 8-bit" if quantise else "")


@dataclass
class TorusPixels:
    """The torus's view and, over its hit pixels, the normal map's normals (world, tangent space), the light's
    samples, and the reference E (hit pixels, 3)."""

    view: TorusView
    n_world: np.ndarray
    n_tangent: np.ndarray
    directions: np.ndarray
    weighted: np.ndarray
    reference: np.ndarray


def torus_reference(probe: np.ndarray, width: int = 160, height: int = 120, light_size: int = 32,
                    normal_depth: float = 0.6, visibility: np.ndarray | None = None) -> TorusPixels:
    """The torus's view, its pixels' tangent-space normals (the normal map's), the probe's samples at
    light_size² and the per-pixel reference E over the hit pixels: the perturbed normal's cosine over the
    surface's own hemisphere (light from below it is hidden by the surface), a ray to each environment
    texel for the visibility (torus and table). visibility: the (K, hit pixels) rays seen, when known
    (reference_visibility: it does not depend on the light)."""
    view = torus_view(width, height)
    hit = view.hit
    texel = sample_periodic(ridges_normal_map(depth=normal_depth), view.uv[hit])
    n_world = perturbed_normal(view.normals[hit], view.tangents[hit], texel)
    n_tangent = normalize(2.0 * texel - 1.0)
    directions, weighted = probe_samples(to_layout(probe, "anglemap", light_size))
    if visibility is None:
        visibility = reference_visibility(view, directions)
    reference = np.einsum("kt,kc->tc", np.maximum(directions @ n_world.T, 0.0) * visibility, weighted)
    return TorusPixels(view, n_world, n_tangent, directions, weighted, reference)


def reference_visibility(view: TorusView, directions: np.ndarray) -> np.ndarray:
    """(K, hit pixels): whether each pixel's point sees each direction (above its surface, no hit)."""
    n_g, points = view.normals[view.hit], view.points[view.hit]
    seen = np.zeros((len(directions), len(n_g)), bool)
    for start in range(0, len(n_g), 64):
        sl = slice(start, start + 64)
        rays = np.broadcast_to(directions[:, None, :], (len(directions), len(n_g[sl]), 3))
        seen[:, sl] = (directions @ n_g[sl].T > 0) & ~_blocked(points[sl], rays)
    return seen


def compare_on_torus(probe: np.ndarray, lightings: list[tuple[Basis, int, bool]], width: int = 160, height: int = 120,
                     lightmap_size: tuple[int, int] = (32, 64), light_size: int = 32,
                     normal_depth: float = 0.6) -> InmComparison:
    """The torus under an angle-map probe (world frame): the per-pixel reference, the thesis's lighting,
    and one INM render per (basis, count, quantise). The reference and the light maps sum the probe
    resampled to light_size² (every texel's energy kept) with a ray to each texel for the visibility; the
    thesis's irradiance map and AO map are its own (accurate, rays). With quantise, the light map goes
    through the spec's 8-bit storage (encode_8bit) first."""
    pixels = torus_reference(probe, width, height, light_size, normal_depth)
    view, n_world, n_tangent, directions, weighted = (pixels.view, pixels.n_world, pixels.n_tangent, pixels.directions,
                                                      pixels.weighted)
    hit, reference = view.hit, pixels.reference
    # INM: the directional light map at the light-map texel, evaluated with the tangent-space normal.
    lm_points, lm_normals, lm_tangents = torus_texels(MAJOR, MINOR, lightmap_size)
    surface = Surface(lm_points, lm_normals, lm_tangents, np.ones(lightmap_size, bool))
    inm = {}
    for basis, count, quantise in lightings:
        coefficients = bake_directional(surface, basis, count, directions, weighted, _blocked)
        if quantise:
            scale = float(coefficients[..., 0, :].max())
            coefficients = decode_8bit(encode_8bit(coefficients, scale), scale)
        c = sample_periodic(coefficients.reshape(*lightmap_size, -1), view.uv[hit]).reshape(-1, count, 3)
        inm[lighting_label(basis, count, quantise)] = np.einsum("tb,tbc->tc", basis.evaluate(n_tangent, count), c) / np.pi
    # Thesis: the irradiance map (E / pi) with the perturbed normal, times the AO light map.
    irradiance_map = accurate_maps(to_layout(probe, "anglemap", 64), [1.0])[0]
    ao = sample_periodic(bake_torus_occlusion(MAJOR, MINOR, lightmap_size, rays=256), view.uv[hit])
    thesis = sample_anglemap(irradiance_map, n_world) * ao

    def image(values):
        out = np.zeros((height, width, 3))
        out[hit] = values
        return out

    return InmComparison(image(reference / np.pi), image(thesis), {k: image(v) for k, v in inm.items()}, hit)


def srgb8(radiance: np.ndarray, exposure: float) -> np.ndarray:
    """8-bit sRGB of radiance x exposure (clipped)."""
    v = np.clip(radiance * exposure, 0.0, 1.0)
    v = np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)
    return np.round(v * 255).astype(np.uint8)


def scores(c: InmComparison) -> dict[str, dict[str, float]]:
    """Per lighting (the thesis's and each INM's): FLIP (LDR, on one exposure: the reference's 99th
    percentile to 0.9) and the mean squared error of the radiance over the reference's mean square."""
    from arsim.evaluate.flip import masked_flip

    exposure = 0.9 / float(np.percentile(c.reference[c.hit].max(axis=-1), 99))
    ref8 = srgb8(c.reference, exposure)
    power = float((c.reference[c.hit] ** 2).mean())
    out = {}
    for name, image in {"thesis": c.thesis, **c.inm}.items():
        out[name] = {"flip": masked_flip(ref8, srgb8(image, exposure), c.hit),
                     "mse": float(((image[c.hit] - c.reference[c.hit]) ** 2).mean()) / power}
    return out


def comparison_strip(c: InmComparison, path) -> None:
    """reference | thesis | each INM, side by side on the reference's exposure, labelled (PNG)."""
    import cv2

    from arsim.core.files import write_bytes_atomic
    from arsim.core.png import png_bytes

    exposure = 0.9 / float(np.percentile(c.reference[c.hit].max(axis=-1), 99))
    tiles = []
    for name, image in {"reference": c.reference, "thesis (AO)": c.thesis, **c.inm}.items():
        tile = np.ascontiguousarray(srgb8(image, exposure))
        cv2.putText(tile, name, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(tile)
    write_bytes_atomic(path, png_bytes(np.concatenate(tiles, axis=1)))
