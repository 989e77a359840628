"""Light maps for meshes read from files: a second UV set unwrapped for them (xatlas: charts without
overlap, packed with a gutter between them), the light map's texels on the surface (each texel's
triangle rasterised in that UV set), and ray casts against the meshes for visibility (Embree).

A file's own UVs serve the normal map and may overlap or repeat; a light map needs every texel to belong
to one point of the surface, so it gets its own set.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from arsim.core.conventions import normalize, texture_texel_uv
from arsim.core.errors import ArsimError
from arsim.lighting.bases.lightmap import Surface
from arsim.render.meshes import Mesh

GUTTER = 2  # texels between charts; the texels around a chart take its border's values (bilinear lookups)
SUBPIXEL_BITS = 8  # cv2's fixed-point fraction for the triangles' corners


def lightmap_unwrap(mesh: Mesh, size: int) -> tuple[Mesh, tuple[int, int]]:
    """The mesh with a second UV set for a light map of at most size x size texels, and that map's
    (height, width): xatlas's charts packed into one atlas with GUTTER texels between them, the scale as
    large as still fits (vertices on chart seams are split)."""
    import xatlas

    area = 0.5 * np.linalg.norm(np.cross(*(mesh.positions[mesh.indices[:, k]] - mesh.positions[mesh.indices[:, 0]]
                                          for k in (1, 2))), axis=1).sum()
    fill = 0.6  # the share of the atlas the charts are first given; less until they fit in one
    while True:
        atlas = xatlas.Atlas()
        atlas.add_mesh(mesh.positions, mesh.indices)
        pack = xatlas.PackOptions()
        pack.resolution, pack.padding, pack.bilinear = size, GUTTER, True
        pack.texels_per_unit = float(size * np.sqrt(fill / max(area, 1e-30)))
        atlas.generate(pack_options=pack)
        if atlas.atlas_count == 1:
            break
        if fill < 1e-3:
            raise ArsimError(f"the mesh's {atlas.chart_count} light-map charts do not fit one {size} x {size} atlas; "
                             f"give a larger lightmap_size")
        fill *= 0.8
    vertex, indices, uvs2 = atlas[0]
    unwrapped = Mesh(mesh.positions[vertex], mesh.normals[vertex], mesh.tangents[vertex], mesh.uvs[vertex],
                     np.ascontiguousarray(uvs2, dtype=np.float32), np.ascontiguousarray(indices, dtype=np.uint32))
    return unwrapped, (atlas.height, atlas.width)


def texel_triangles(uvs: np.ndarray, indices: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) the triangle each texel of a light map lies on (-1: none), rasterised in the UV set uvs
    (V, 2); row 0 at v = 1. cv2 fills every texel a triangle touches, so that edges leave no gaps."""
    h, w = shape
    corners = np.stack([uvs[:, 0] * w - 0.5, (1.0 - uvs[:, 1]) * h - 0.5], axis=-1)  # texel centres at integers
    fixed = np.round(corners[indices] * (1 << SUBPIXEL_BITS)).astype(np.int32)  # (T, 3, 2)
    ids = np.full((h, w), -1, dtype=np.int32)
    for k, triangle in enumerate(fixed):
        cv2.fillConvexPoly(ids, triangle, int(k), lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
    return ids


def _barycentric(mesh: Mesh, triangles: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(..., 3) the barycentric coordinates of the UV points (u, v) (...) in the second UV set's triangles (...)."""
    tri = mesh.indices[triangles].astype(np.int64)
    a, b, c = (mesh.uvs2[tri[..., k]].astype(np.float64) for k in range(3))
    e1, e2 = b - a, c - a
    d = np.stack([u, v], axis=-1) - a
    det = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    det = np.where(np.abs(det) > 1e-20, det, 1e-20)
    l1 = (d[..., 0] * e2[..., 1] - d[..., 1] * e2[..., 0]) / det
    l2 = (e1[..., 0] * d[..., 1] - e1[..., 1] * d[..., 0]) / det
    return np.stack([1.0 - l1 - l2, l1, l2], axis=-1)


def lightmap_texels(mesh: Mesh, model: np.ndarray, shape: tuple[int, int]) -> Surface:
    """The light map's texels on a mesh placed by `model` (object to world): per texel on a triangle of the
    second UV set, the world point, normal and tangent at its centre (barycentric); texels within GUTTER
    of a chart take the nearest chart texel's (they are only read by bilinear lookups at the chart's
    border)."""
    ids = texel_triangles(mesh.uvs2, mesh.indices, shape)
    covered = ids >= 0
    if not covered.any():
        return Surface(*(np.zeros(shape + (3,)) for _ in range(3)), covered)
    distance, (rows, cols) = ndimage.distance_transform_edt(~covered, return_indices=True)
    near = distance <= GUTTER * np.sqrt(2.0)
    h, w = shape
    u, v = texture_texel_uv(h, w)
    # Gutter texels are placed at their nearest covered texel's centre.
    u, v = np.where(covered, u, u[rows, cols]), np.where(covered, v, v[rows, cols])
    rows, cols = np.where(covered, np.arange(h)[:, None], rows), np.where(covered, np.arange(w), cols)
    # A texel that a triangle only touches may have its centre on a neighbour's triangle: of the triangles
    # at it and its 8 neighbours, the one that holds the centre (the most inside; clamped onto it if none).
    padded = np.pad(ids, 1, constant_values=-1)
    candidates = np.stack([padded[rows + 1 + dr, cols + 1 + dc] for dr in (0, -1, 1) for dc in (0, -1, 1)], axis=-1)
    weights = _barycentric(mesh, np.maximum(candidates, 0), u[..., None], v[..., None])  # (H, W, 9, 3)
    inside = np.where(candidates >= 0, weights.min(axis=-1), -np.inf)
    best = np.argmax(inside, axis=-1)  # (the first, the texel's own, among equals)
    triangle = np.take_along_axis(candidates, best[..., None], axis=-1)[..., 0]
    weights = np.clip(np.take_along_axis(weights, best[..., None, None], axis=-2)[..., 0, :], 0.0, None)
    weights /= np.maximum(weights.sum(axis=-1, keepdims=True), 1e-12)
    tri = mesh.indices[triangle].astype(np.int64)  # (H, W, 3)

    def interpolate(values: np.ndarray) -> np.ndarray:
        return np.einsum("hwk,hwkc->hwc", weights, values[tri].astype(np.float64))

    linear = model[:3, :3]
    points = interpolate(mesh.positions) @ linear.T + model[:3, 3]
    normals = normalize(interpolate(mesh.normals) @ np.linalg.inv(linear))  # (the inverse transpose, row vectors)
    tangents = interpolate(mesh.tangents) @ linear.T
    tangents = normalize(tangents - normals * np.sum(tangents * normals, axis=-1, keepdims=True))
    return Surface(points, normals, tangents, near)


def ray_caster(meshes: list[tuple[Mesh, np.ndarray]], distances: bool = False):
    """blocked(origins (T, 3), directions (K, T, 3)) -> (K, T): whether each ray hits any of the meshes,
    each placed by its model matrix (Embree through trimesh); with distances, how far the first hit is
    (inf: none)."""
    import trimesh
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    parts = []
    for mesh, model in meshes:
        positions = mesh.positions.astype(np.float64) @ model[:3, :3].T + model[:3, 3]
        parts.append(trimesh.Trimesh(positions, mesh.indices, process=False))
    intersector = RayMeshIntersector(trimesh.util.concatenate(parts))

    def blocked(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        origins = np.broadcast_to(origins, directions.shape)
        hit = intersector.intersects_any(origins.reshape(-1, 3), directions.reshape(-1, 3))
        return np.asarray(hit, dtype=bool).reshape(directions.shape[:-1])

    def first_hit(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        o, d = np.broadcast_to(origins, directions.shape).reshape(-1, 3), directions.reshape(-1, 3)
        out = np.full(len(o), np.inf)
        if len(o):
            locations, rays, _ = intersector.intersects_location(o, d, multiple_hits=False)
            if len(rays):
                out[rays] = np.einsum("ij,ij->i", locations - o[rays], d[rays])
        return out.reshape(directions.shape[:-1])

    return first_hit if distances else blocked
