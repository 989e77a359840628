"""Precomputed radiance transfer for the scene's objects (lighting = prt-..., README: Precomputed radiance
transfer): where an object's transfer is taken (its mesh's vertices in world space, as the vertex shader
places them, or its light map's texels), computed once with the scene's visibility and kept on disk, and
the object's material given the variant's matrices and the light's SH to start from."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from arsim.core.conventions import normalize
from arsim.core.errors import ArsimError
from arsim.lighting import prt


@dataclass(frozen=True)
class PrtSettings:
    """An object's [[render.objects]] prt_* keys and its lighting's variant."""

    variant: str
    order: int = prt.DEFAULT_ORDER
    per_texel: bool = False
    samples: int = 2048
    clusters: int = 0  # CPCA clusters (0: none)


def vertex_frames(mesh, model: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A mesh's vertices, normals and tangents in world space (V, 3) as object.vert turns them: the
    model matrix for points, its inverse transpose for normals and tangents."""
    m3 = model[:3, :3].astype(np.float64)
    inverse_t = np.linalg.inv(m3).T
    points = mesh.positions.astype(np.float64) @ m3.T + model[:3, 3]
    normals = normalize(mesh.normals.astype(np.float64) @ inverse_t.T)
    tangents = mesh.tangents.astype(np.float64) @ inverse_t.T
    tangents = normalize(tangents - normals * np.sum(tangents * normals, axis=-1, keepdims=True))
    return points, normals, tangents


_MEMO: dict[str, prt.Transfer] = {}  # (the session computes the captured and the true light's objects)


def object_transfer(obj, settings: PrtSettings, blocked, scene_key: str,
                    progress=None) -> tuple[prt.Transfer, np.ndarray | None]:
    """An object's transfer, and where it is per texel the light map's valid texels (H, W) (None: per
    vertex); computed with `blocked` (the scene's rays) or read from the cache under the geometry's key."""
    valid = None
    if settings.per_texel:
        surface = obj.lightmap_surface() if obj.lightmap_surface is not None else None
        if surface is None or not surface.valid.any():
            raise ArsimError("PRT per texel needs the object's light-map UV set (second texture coordinates), and this "
                             "object has none; give prt_at = \"vertex\", or a mesh with a light-map unwrap")
        valid = surface.valid
        points, normals, tangents = surface.points[valid], surface.normals[valid], surface.tangents[valid]
    else:
        points, normals, tangents = vertex_frames(obj.mesh, obj.model)
    key = prt.transfer_key(points, normals, tangents, settings.order, settings.samples, scene_key)
    if key not in _MEMO:
        _MEMO.clear()  # (one scene at a time)
        _MEMO[key] = prt.cached_transfer(key, lambda: prt.compute_transfer(
            points, normals, tangents, settings.order, blocked, settings.samples, progress=progress))
    return _MEMO[key], valid


def with_transfer(obj, settings: PrtSettings, blocked, scene_key: str, light: np.ndarray):
    """The object with its material's PRT: the variant's matrices (per vertex, or per texel with zeros
    outside the light map's texels), CPCA where asked, and the light's SH (the angle map `light`)."""
    transfer, valid = object_transfer(obj, settings, blocked, scene_key)
    variant = prt.get_variant(settings.variant)
    matrices = prt.variant_transfer(transfer, variant)
    if valid is not None:
        grid = np.zeros(valid.shape + matrices.shape[1:], np.float32)
        grid[valid] = matrices
        matrices = grid
    compressed = None
    if settings.clusters:
        flat = matrices.reshape(-1, *matrices.shape[-2:])
        compressed = prt.compress(flat, settings.clusters)
    material = dataclasses.replace(obj.material, prt_variant=variant.name, prt_matrices=matrices,
                                   prt_compressed=compressed, prt_light=prt.light_sh(light, settings.order))
    return dataclasses.replace(obj, material=material)
