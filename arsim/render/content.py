"""The virtual objects the AR session places on the tag (thesis figure 5.3 and 5.1): a row of spheres
with Phong exponents from 1 to 1280, a torus, non-convex, with a tangent-space normal map and an
ambient-occlusion light map that arsim bakes itself by casting rays against the torus and the table,
and meshes read from files.

Object space: y up, the object standing on the table plane y = 0.
"""

from __future__ import annotations

import numpy as np

from arsim.core.conventions import normalize
from arsim.core.errors import ArsimError
from arsim.render.meshes import Mesh, grid_mesh, load_mesh, uv_sphere
from arsim.render.renderer import Material, SceneObject

SPHERE_EXPONENTS = (1.0, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0, 1280.0)  # thesis figure 5.3


def torus_surface(u: np.ndarray, v: np.ndarray, major: float, minor: float) -> tuple[np.ndarray, ...]:
    """Points, normals and tangents (along increasing u) of a torus around the y axis resting on y = 0:
    u runs around the ring, v around the tube (v = 0 on its outer equator, 0.25 on top)."""
    a, b = 2.0 * np.pi * np.asarray(u), 2.0 * np.pi * np.asarray(v)
    ring = np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], axis=-1)
    up = np.array([0.0, 1.0, 0.0])
    normal = ring * np.cos(b)[..., None] + up * np.sin(b)[..., None]
    point = ring * major + normal * minor + up * minor
    tangent = np.stack([np.cos(a), np.zeros_like(a), -np.sin(a)], axis=-1)
    return point, normal, tangent


def torus(major: float = 0.05, minor: float = 0.02, rings: int = 96, segments: int = 48) -> Mesh:
    """The torus mesh; both UV sets are (u, v) (the light map is baked in the same parameterisation)."""
    u, v = np.meshgrid(np.linspace(0.0, 1.0, rings + 1), np.linspace(0.0, 1.0, segments + 1), indexing="ij")
    return grid_mesh(*torus_surface(u, v, major, minor), np.stack([u, v], axis=-1))


def torus_distance(p: np.ndarray, major: float, minor: float) -> np.ndarray:
    """Signed distance to the torus resting on y = 0."""
    q = np.stack([np.hypot(p[..., 0], p[..., 2]) - major, p[..., 1] - minor], axis=-1)
    return np.linalg.norm(q, axis=-1) - minor


def scene_distance(p: np.ndarray, major: float, minor: float) -> np.ndarray:
    """Distance to the nearest of the torus and the table top (y = 0)."""
    return np.minimum(torus_distance(p, major, minor), p[..., 1])


def sphere_trace(origins: np.ndarray, directions: np.ndarray, distance, scale: float, reach: float,
                 steps: int = 96) -> np.ndarray:
    """Whether each ray (origins and directions broadcast together, (..., 3)) hits the surface of the
    distance function `distance` within `reach`: sphere tracing, each step the distance to the nearest
    surface; scale is the scene's small length (the hit and the step floors are fractions of it)."""
    travelled = np.full(np.broadcast_shapes(origins.shape, directions.shape)[:-1], 1e-3 * scale)
    hit = np.zeros(travelled.shape, dtype=bool)
    for _ in range(steps):
        p = origins + directions * travelled[..., None]
        d = distance(p)
        hit |= d < 1e-4 * scale
        travelled = np.where(hit, travelled, travelled + np.maximum(d, 1e-5 * scale))
        if ((travelled > reach) | hit).all():
            break
    return hit


def torus_texels(major: float, minor: float, size: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """Points, normals and tangents (H, W, 3) of the torus at the centres of an H x W texture's texels,
    row 0 at v = 1 (the light map's and the normal map's parameterisation)."""
    h, w = size
    v, u = np.meshgrid((h - 1 - np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    return torus_surface(u, v, major, minor)


def tangent_frames(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Any right-handed (t, b) completing unit normals (..., 3) to a frame."""
    helper = np.where(np.abs(normal[..., 1:2]) < 0.9, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    t_axis = normalize(np.cross(helper, normal))
    return t_axis, np.cross(normal, t_axis)


def bake_torus_occlusion(major: float = 0.05, minor: float = 0.02, size: tuple[int, int] = (64, 128),
                         rays: int = 96, seed: int = 0) -> np.ndarray:
    """Ambient-occlusion light map (H, W, 3) of the torus on the table, row 0 at v = 1: per texel, the
    fraction of cosine-weighted rays from the surface that escape the torus and the table top (sphere
    tracing of the exact distance functions). 1 on the top of the ring, near 0 where it touches the table."""
    point, normal, _ = torus_texels(major, minor, size)
    rng = np.random.default_rng(seed)
    # Cosine-weighted directions around each normal (stratified: a side x side grid of the two random numbers).
    side = int(np.sqrt(rays))
    xi = (np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2)
          + rng.random((side * side, 2))) / side
    radius, angle = np.sqrt(xi[:, 0]), 2.0 * np.pi * xi[:, 1]
    local = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.sqrt(1.0 - xi[:, 0])], -1)
    t_axis, b_axis = tangent_frames(normal)
    directions = (local[:, 0, None, None, None] * t_axis + local[:, 1, None, None, None] * b_axis
                  + local[:, 2, None, None, None] * normal)  # (R, H, W, 3)
    origin = point + normal * (1e-3 * minor)
    hit = sphere_trace(origin, directions, lambda p: scene_distance(p, major, minor), minor, 6.0 * (major + minor))
    occlusion = (~hit).mean(axis=0)
    return np.repeat(occlusion[..., None], 3, axis=-1).astype(np.float32)


def ridges_normal_map(size: tuple[int, int] = (128, 256), ridges: tuple[int, int] = (24, 8),
                      depth: float = 0.6) -> np.ndarray:
    """A tangent-space normal map (H, W, 3) in [0, 1] (eq. 5.1) of a height field of crossed ridges
    h = depth sin(2 pi k u) sin(2 pi m v) / (2 pi k) (slopes up to `depth`), row 0 at v = 1."""
    h, w = size
    v, u = np.meshgrid((h - 1 - np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    k, m = ridges
    du = depth * np.cos(2 * np.pi * k * u) * np.sin(2 * np.pi * m * v)
    dv = depth * (m / k) * np.sin(2 * np.pi * k * u) * np.cos(2 * np.pi * m * v)
    n = normalize(np.stack([-du, -dv, np.ones_like(du)], axis=-1))
    return (n * 0.5 + 0.5).astype(np.float32)


def _chord_gap(radius: float, steps_per_turn: int) -> float:
    """How far a polygon of steps_per_turn sides inscribed in a circle of this radius departs from it."""
    return radius * (1.0 - np.cos(np.pi / steps_per_turn))


def torus_lods(major: float, minor: float, rings: int) -> tuple[tuple[Mesh, float], ...]:
    """Coarser tori than rings x rings / 2, down to 16 x 8, with their departures from the torus (the ring's
    and the tube's chord gaps added)."""
    steps = [r for r in (64, 48, 32, 24, 16) if r < rings]
    return tuple((torus(major, minor, r, r // 2), _chord_gap(major + minor, r) + _chord_gap(minor, r // 2)) for r in steps)


def translation(x: float, y: float, z: float) -> np.ndarray:
    model = np.eye(4)
    model[:3, 3] = [x, y, z]
    return model


def scene_objects(section) -> list[SceneObject]:
    """The scenario's virtual objects ([[render.objects]], a RenderObjectSection each) as SceneObjects; a
    mesh that cannot be read raises ArsimError."""
    objects = []
    for o in section.objects:
        x, z = o.position_m
        if o.kind == "sphere_row":
            spacing = 2.6 * o.size_m
            for k, exponent in enumerate(SPHERE_EXPONENTS):
                dx = (k - (len(SPHERE_EXPONENTS) - 1) / 2) * spacing
                objects.append(SceneObject(uv_sphere(o.size_m, 32, 64), Material(o.kd, o.ks, exponent, method=o.method),
                                           translation(x + dx, o.size_m, z), sphere=o.size_m))
        elif o.kind == "sphere":
            objects.append(SceneObject(uv_sphere(o.size_m, 48, 96), Material(o.kd, o.ks, o.exponent, method=o.method),
                                       translation(x, o.size_m, z), sphere=o.size_m))
        elif o.kind == "mesh":
            objects.append(mesh_object(o))
        else:
            minor = 0.4 * o.size_m
            objects.append(SceneObject(torus(o.size_m, minor), Material(
                o.kd, o.ks, o.exponent, bake_torus_occlusion(o.size_m, minor) if o.light_map else None,
                ridges_normal_map() if o.normal_map else None, o.method), translation(x, 0.0, z),
                torus_lods(o.size_m, minor, 96)))
    return objects


def mesh_object(o) -> SceneObject:
    """A mesh file's object: scaled so that its bounding box's largest side is size_m, standing on the
    table (its lowest point at y = 0) with its box centred over position_m; the ridges normal map where
    it has texture coordinates."""
    if o.mesh is None:
        raise ArsimError("[[render.objects]] kind = \"mesh\" needs mesh = \"FILE\" (an OBJ, PLY, STL, OFF or glTF file)")
    mesh, textured = load_mesh(o.mesh)
    low, high = mesh.positions.min(axis=0).astype(np.float64), mesh.positions.max(axis=0).astype(np.float64)
    extent = float((high - low).max())
    if extent <= 0.0:
        raise ArsimError(f"{o.mesh}: the mesh has no extent (all its vertices coincide); fix the file")
    scale = o.size_m / extent
    centre = (low + high) / 2
    model = translation(o.position_m[0] - scale * centre[0], -scale * low[1], o.position_m[1] - scale * centre[2])
    model[:3, :3] *= scale
    return SceneObject(mesh, Material(o.kd, o.ks, o.exponent, None, ridges_normal_map() if o.normal_map and textured else None,
                                      o.method), model)
