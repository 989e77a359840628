"""The lighting-estimation literature's three spheres (README: Light estimation): diffuse, matte silver
and mirror, seen orthographically from +z (image right +x, up +y), lit by a light estimate (its SH ambient
and main light for the diffuse sphere, its cubemap for the two others: estimate.lit) or by the true light
(its angle map), in NumPy, linear radiance. Scored with light_metrics over the spheres' disks and HDR-FLIP on the mirror.
"""

from __future__ import annotations

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles
from arsim.core.resample import sample_anglemap, to_layout
from arsim.estimate.lit import irradiance, lobe_average, lobe_average_of
from arsim.estimate.shapes import cube_texels

SIZE = 64  # pixels across each sphere
ALBEDO = 0.8  # the diffuse sphere's
SILVER_EXPONENT = 32.0  # the matte silver's Phong lobe about the mirror direction
LIGHT_SIDE = 64  # the true light's angle map the diffuse and silver spheres sum over


def sphere_geometry(size: int = SIZE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mask (S, S), normals (S, S, 3), mirror directions (S, S, 3)) of a unit sphere seen from +z."""
    c = (np.arange(size) + 0.5) / size * 2 - 1
    x, y = np.meshgrid(c, -c)  # row 0 at the top: +y
    r2 = x * x + y * y
    mask = r2 < 1.0
    z = np.sqrt(np.clip(1 - r2, 0.0, None))
    n = np.stack([x, y, z], axis=-1)
    view = np.array([0.0, 0.0, -1.0])
    mirror = view - 2 * (n @ view)[..., None] * n
    return mask, n, mirror


def truth_spheres(anglemap: np.ndarray, size: int = SIZE) -> np.ndarray:
    """(3, S, S, 3): the three spheres lit by an angle-map light: the diffuse one by the exact cosine sum,
    the silver by the lobe average, the mirror by a bilinear lookup (0 off the disks)."""
    mask, n, mirror = sphere_geometry(size)
    light = to_layout(np.asarray(anglemap, dtype=np.float32)[..., :3], "anglemap", LIGHT_SIDE)
    inside = anglemap_disk_mask(LIGHT_SIDE)
    d, radiance, omega = anglemap_directions(LIGHT_SIDE)[inside], light[inside].astype(np.float64), anglemap_solid_angles(LIGHT_SIDE)[inside]
    out = np.zeros((3, size, size, 3))
    out[0][mask] = ALBEDO / np.pi * (np.maximum(n[mask] @ d.T, 0.0) @ (radiance * omega[:, None]))
    out[1][mask] = lobe_average_of(d, radiance, omega, mirror[mask], SILVER_EXPONENT)
    out[2][mask] = sample_anglemap(np.asarray(anglemap, dtype=np.float32)[..., :3], mirror[mask])
    return out


def estimate_spheres(sh_radiance: np.ndarray, main_direction: np.ndarray, main_intensity: np.ndarray,
                     cubemap: np.ndarray | None, size: int = SIZE) -> np.ndarray:
    """(3, S, S, 3): the three spheres lit by an estimate as a renderer lights with it (estimate.lit): the
    diffuse one by its SH ambient and main light, the silver by the lobe average over its cubemap's texels,
    the mirror by its cubemap's texel in the mirror direction (nearest: the cubemap is what the platform
    gives); no cubemap (a file's estimate): the silver and mirror spheres black."""
    mask, n, mirror = sphere_geometry(size)
    out = np.zeros((3, size, size, 3))
    out[0][mask] = ALBEDO / np.pi * irradiance(sh_radiance, main_direction, main_intensity, n[mask])
    if cubemap is not None:
        faces = np.asarray(cubemap, dtype=np.float64)
        out[1][mask] = lobe_average(faces, mirror[mask], SILVER_EXPONENT)
        f, r, c = cube_texels(mirror[mask], faces.shape[1])
        out[2][mask] = faces[f, r, c]
    return out


def sphere_scores(estimate: np.ndarray, truth: np.ndarray) -> dict:
    """Per sphere (diffuse, silver, mirror): si-RMSE, RMSE, RGB angular error over its disk; and the mirror's
    HDR-FLIP."""
    import flip_evaluator

    from arsim.evaluate.light_metrics import angular_error_deg, rmse, si_rmse

    mask = sphere_geometry(truth.shape[1])[0]
    out = {}
    for k, name in enumerate(("diffuse", "silver", "mirror")):
        out[name] = {"si_rmse": si_rmse(estimate[k], truth[k], mask), "rmse": rmse(estimate[k], truth[k], mask),
                     "angular_deg": angular_error_deg(estimate[k], truth[k], mask)}
    error, _, _ = flip_evaluator.evaluate(np.ascontiguousarray(truth[2], dtype=np.float32),
                                          np.ascontiguousarray(np.maximum(estimate[2], 0.0), dtype=np.float32), "HDR",
                                          applyMagma=False)
    out["mirror"]["hdr_flip"] = float(np.asarray(error)[mask].mean())
    return out
