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
    bounces: int = 0  # 1: one bounce of interreflection off the objects that stand still and the table
    albedo: float = 0.5  # the object's diffuse reflectance (grey: the mean of its k_d) for the light it sends on
    table_albedo: float = 0.2  # the table's (grey: the mean of [ar] table_albedo)


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
BOUNCE_SAMPLES = 2000  # points per object where the light it sends on is sampled (by area)
BOUNCE_DIRECTIONS = 256  # directions of their transfer (the bounced light is smooth)
TABLE_GRID = 48  # the table's points: a grid over the objects' box, twice its size each way


def bounce_gather(occlusion, order: int, table_albedo: float) -> prt.Bounce:
    """bounce(hit points, directions) for one bounce: the light a point of the scene sends back, albedo / pi
    times the shadowed diffuse transfer (direct light only) at the nearest of sample points spread over the
    objects that stand still (by area) and a grid on the table around them."""
    import trimesh
    from scipy.spatial import cKDTree

    points, normals, albedo = [], [], []
    for k, o in enumerate(occlusion.occluders):
        positions = o.mesh.positions.astype(np.float64) @ o.model[:3, :3].T + o.model[:3, 3]
        surface = trimesh.Trimesh(positions, o.mesh.indices, process=False)
        where, faces = trimesh.sample.sample_surface(surface, BOUNCE_SAMPLES, seed=k)
        points.append(where)
        normals.append(surface.face_normals[faces])
        albedo.append(np.full(len(where), float(np.mean(o.material.kd))))
    boxes = np.concatenate([o.corners() for o in occlusion.occluders]) if occlusion.occluders else np.zeros((1, 3))
    centre, half = (boxes.min(axis=0) + boxes.max(axis=0)) / 2, np.maximum((boxes.max(axis=0) - boxes.min(axis=0)), 0.05)
    x, z = np.meshgrid(*(centre[i] + np.linspace(-1.0, 1.0, TABLE_GRID) * half[i] for i in (0, 2)), indexing="ij")
    points.append(np.stack([x.ravel(), np.full(x.size, 1e-4), z.ravel()], axis=-1))
    normals.append(np.tile([0.0, 1.0, 0.0], (x.size, 1)))
    albedo.append(np.full(x.size, table_albedo))
    points, normals, albedo = np.concatenate(points), normalize(np.concatenate(normals)), np.concatenate(albedo)
    helper = np.where(np.abs(normals[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    tangents = normalize(np.cross(helper, normals))
    key = prt.transfer_key("bounce", points, normals, order, BOUNCE_DIRECTIONS, occlusion.key)
    sent = prt.cached_transfer(key, lambda: prt.compute_transfer(points + normals * 1e-5, normals, tangents, order,
                                                                 occlusion.blocked, BOUNCE_DIRECTIONS))
    radiance = sent.shadowed * (albedo / np.pi)[:, None]
    tree = cKDTree(points)

    def bounce(hits: np.ndarray, directions: np.ndarray) -> np.ndarray:
        return radiance[tree.query(hits)[1]]

    return bounce


def object_transfer(obj, settings: PrtSettings, occlusion, progress=None) -> tuple[prt.Transfer, np.ndarray | None]:
    """An object's transfer, and where it is per texel the light map's valid texels (H, W) (None: per
    vertex); computed with the scene's rays (content.Occlusion) or read from the cache under the geometry's
    key."""
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
    bounced = (settings.bounces, settings.albedo, settings.table_albedo) if settings.bounces else 0
    key = prt.transfer_key(points, normals, tangents, settings.order, settings.samples, occlusion.key, bounced)
    if key not in _MEMO:
        _MEMO.clear()  # (one scene at a time)

        def compute():
            if not settings.bounces:
                return prt.compute_transfer(points, normals, tangents, settings.order, occlusion.blocked, settings.samples,
                                            progress=progress)
            return prt.compute_transfer(points, normals, tangents, settings.order, samples=settings.samples, progress=progress,
                                        distance=occlusion.distance,
                                        bounce=bounce_gather(occlusion, settings.order, settings.table_albedo))

        _MEMO[key] = prt.cached_transfer(key, compute)
    return _MEMO[key], valid


def with_transfer(obj, settings: PrtSettings, occlusion, light: np.ndarray):
    """The object with its material's PRT: the variant's matrices (per vertex, or per texel with zeros
    outside the light map's texels), CPCA where asked, and the light's SH (the angle map `light`)."""
    transfer, valid = object_transfer(obj, settings, occlusion)
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
