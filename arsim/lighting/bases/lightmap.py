"""Directional light maps (irradiance normal mapping, spec 2.2): per texel of a surface, the irradiance
for every normal of its tangent-space hemisphere, with visibility, projected into a basis.

Per texel, the radiance it sees is the environment's texels in its hemisphere, each with its solid
angle, dropped where a ray towards it hits the scene (summing over the environment's texels rather than
over rays in fixed directions keeps every light source's energy however small it is). Two routes:
- `direct` (default): the irradiance at the normals of a hemisphere rule, fitted into the basis by least
  squares over that rule: the best the basis can hold;
- `sh9`, the spec's (2.2.1, listing 2.1): the radiance projected into SH bands 0-2 in the texel's
  tangent frame, convolved with the clamped cosine, then fitted into the basis over the hemisphere (for
  the modified H-basis, listing 2.1's matrix): it fits the irradiance band-limited to bands 0-2, not
  the irradiance itself.
Storage as the spec's 2.2.3 (the constant term in sRGB, the others range-compressed into 8 bits) or as
float: `encode_8bit`/`decode_8bit`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles
from arsim.core.errors import ArsimError
from arsim.lighting.bases.functions import Basis, sh9
from arsim.lighting.bases.irradiance import COSINE_KERNEL
from arsim.lighting.bases.projection import from_sh9_matrix
from arsim.lighting.bases.quadrature import hemisphere_quadrature

RANGE = 0.75  # the spec's range-compression factor for the coefficients after the constant one


def probe_samples(probe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An angle map's disk texels as (K, 3) world directions and (K, 3) radiance x solid angle."""
    n = probe.shape[0]
    inside = anglemap_disk_mask(n)
    weights = anglemap_solid_angles(n)[inside]
    return anglemap_directions(n)[inside], probe[inside][:, :3].astype(np.float64) * weights[:, None]


@dataclass(frozen=True)
class Surface:
    """The texels of a light map: world points, unit normals and tangents (H, W, 3), and which texels are
    on the surface (H, W). The bitangent is normal x tangent (the renderer's)."""

    points: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    valid: np.ndarray


FIT_RULE = (12, 24)  # the normals the direct route fits at: 288 over the hemisphere


def _direct_fit(basis: Basis, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The fit rule's normals (J, 3) and the (count, J) matrix of the weighted least-squares fit at them."""
    normals, weights = hemisphere_quadrature(*FIT_RULE)
    b = basis.evaluate(normals, count)
    weighted = (b * weights[:, None]).T  # (count, J)
    return normals, np.linalg.solve(weighted @ b, weighted)


def bake_directional(surface: Surface, basis: Basis, count: int, directions: np.ndarray, radiance_weighted: np.ndarray,
                     blocked: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None, route: str = "direct",
                     chunk: int = 64) -> np.ndarray:
    """Coefficients (H, W, count, 3) of each valid texel's directional irradiance (0 elsewhere), from
    environment samples (K, 3) with radiance x solid angle (K, 3) (probe_samples). blocked(origins (T, 3),
    directions (K, T, 3)) -> (K, T) bool, True where the ray hits the scene (None: nothing occludes)."""
    basis.check(count)
    if route not in ("direct", "sh9"):
        raise ArsimError(f"light-map route '{route}': use direct or sh9")
    if route == "sh9":
        to_basis = from_sh9_matrix(basis, count) * COSINE_KERNEL  # (count, 9): convolution, then the fit
    else:
        fit_normals, fit = _direct_fit(basis, count)
    h, w = surface.valid.shape
    out = np.zeros((h * w, count, 3))
    index = np.flatnonzero(surface.valid.reshape(-1))
    points, normals = surface.points.reshape(-1, 3)[index], surface.normals.reshape(-1, 3)[index]
    tangents = surface.tangents.reshape(-1, 3)[index]
    frames = np.stack([tangents, np.cross(normals, tangents), normals], axis=1)  # (T, 3, 3): rows t, b, n
    for start in range(0, len(index), chunk):
        sl = slice(start, start + chunk)
        local = np.matmul(directions, frames[sl].transpose(0, 2, 1)).transpose(1, 0, 2)  # (K, T, 3) in each texel's frame
        weight = (local[..., 2] > 0).astype(np.float64)
        if blocked is not None:
            weight *= ~blocked(points[sl], np.broadcast_to(directions[:, None, :], local.shape))
        if route == "sh9":
            sh = np.einsum("kts,kt,kc->tsc", sh9(local), weight, radiance_weighted)  # (T, 9, 3)
            out[index[sl]] = np.einsum("bs,tsc->tbc", to_basis, sh)
        else:
            # (matmul rather than einsum: BLAS, ten times as fast here)
            cosines = np.maximum(local @ fit_normals.T, 0.0) * weight[..., None]  # (K, T, J)
            e = np.matmul(cosines.transpose(1, 2, 0), radiance_weighted)  # (T, J, 3) at the fit rule's normals
            out[index[sl]] = np.matmul(fit, e)
    return out.reshape(h, w, count, 3)


def encode_8bit(coefficients: np.ndarray, scale: float) -> np.ndarray:
    """Spec 2.2.3: coefficients (..., count, 3) over `scale` (the constant term's largest) stored in 8
    bits: the constant term as sRGB-like gamma 1/2.2, the others range-compressed from [-RANGE, RANGE]."""
    c = np.asarray(coefficients, dtype=np.float64) / scale
    out = np.empty_like(c)
    out[..., 0, :] = np.clip(c[..., 0, :], 0.0, 1.0) ** (1 / 2.2)
    out[..., 1:, :] = np.clip((c[..., 1:, :] + RANGE) / (2 * RANGE), 0.0, 1.0)
    return np.round(out * 255).astype(np.uint8)


def decode_8bit(codes: np.ndarray, scale: float) -> np.ndarray:
    """The inverse of encode_8bit (what the shader's sRGB and linear lookups give)."""
    v = np.asarray(codes, dtype=np.float64) / 255
    out = np.empty_like(v)
    out[..., 0, :] = v[..., 0, :] ** 2.2
    out[..., 1:, :] = v[..., 1:, :] * 2 * RANGE - RANGE
    return out * scale


def bake_irradiance_volume(points: np.ndarray, directions: np.ndarray, radiance_weighted: np.ndarray,
                           blocked: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
                           chunk: int = 64) -> np.ndarray:
    """Irradiance volume (spec 1.9, 2.5.2) for objects that move: at grid points (..., 3), the irradiance
    over the whole sphere of normals as convolved SH bands 0-2 in world axes, (..., 9, 3), from the
    environment samples with a ray to each for the visibility of the static scene."""
    flat = points.reshape(-1, 3)
    out = np.zeros((len(flat), 9, 3))
    basis = sh9(directions)  # (K, 9)
    for start in range(0, len(flat), chunk):
        sl = slice(start, start + chunk)
        weight = np.ones((len(directions), len(flat[sl])))
        if blocked is not None:
            weight = weight * ~blocked(flat[sl], np.broadcast_to(directions[:, None, :], (len(directions), len(flat[sl]), 3)))
        out[sl] = np.einsum("ks,kt,kc->tsc", basis, weight, radiance_weighted) * COSINE_KERNEL[:, None]
    return out.reshape(points.shape[:-1] + (9, 3))


def sample_volume(volume: np.ndarray, low: np.ndarray, high: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Trilinear lookup (..., 9, 3) of a volume (X, Y, Z, 9, 3) whose grid spans the box low..high (grid
    points on its corners), clamped at the box's faces."""
    shape = np.array(volume.shape[:3])
    f = (np.asarray(points, dtype=np.float64) - low) / (np.asarray(high) - low) * (shape - 1)
    f = np.clip(f, 0.0, shape - 1)
    i0 = np.minimum(np.floor(f).astype(int), shape - 2).clip(0)
    a = f - i0
    out = 0.0
    for corner in np.ndindex(2, 2, 2):
        c = np.array(corner)
        weight = np.prod(np.where(c, a, 1.0 - a), axis=-1)
        idx = np.minimum(i0 + c, shape - 1)
        out = out + weight[..., None, None] * volume[idx[..., 0], idx[..., 1], idx[..., 2]]
    return out


def volume_irradiance(coefficients: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """E (..., 3) at world normals from a volume's convolved SH (..., 9, 3)."""
    return np.einsum("...s,...sc->...c", sh9(normals), coefficients)
