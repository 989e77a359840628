"""Meshes of the virtual objects: positions, normals, per-vertex tangents, two UV sets (normal map and
light map) and triangle indices, in object space (y up)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arsim.core.errors import ArsimError


@dataclass(frozen=True)
class Mesh:
    positions: np.ndarray  # (V, 3) float32
    normals: np.ndarray  # (V, 3)
    tangents: np.ndarray  # (V, 3): along increasing u of the first UV set
    uvs: np.ndarray  # (V, 2): normal map
    uvs2: np.ndarray  # (V, 2): light map
    indices: np.ndarray  # (T, 3) uint32, counter-clockwise seen from outside

    def interleaved(self) -> np.ndarray:
        """(V, 14) float32 rows: position, normal, tangent, uv, uv2 (the vertex buffer's layout)."""
        return np.hstack([self.positions, self.normals, self.tangents, self.uvs, self.uvs2]).astype(np.float32)


def grid_mesh(points: np.ndarray, normals: np.ndarray, tangents: np.ndarray, uvs: np.ndarray) -> Mesh:
    """A mesh of a parametric surface sampled on a grid (R + 1, S + 1, ...): two triangles per cell,
    counter-clockwise where the second grid axis turns to the first as the normal's right hand; both
    UV sets the grid's (u, v)."""
    rows, cols = points.shape[0] - 1, points.shape[1] - 1
    r, s = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a = r * (cols + 1) + s
    b, c, d = a + cols + 1, a + 1, a + cols + 2
    indices = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([c, b, d], -1).reshape(-1, 3)])
    flat = (lambda x: x.reshape(-1, x.shape[-1]).astype(np.float32))
    return Mesh(flat(points), flat(normals), flat(tangents), flat(uvs), flat(uvs), indices.astype(np.uint32))


def uv_sphere(radius: float = 1.0, rings: int = 48, segments: int = 96) -> Mesh:
    """A latitude-longitude sphere: u = longitude / 2 pi, v = polar angle / pi from the top; the tangent
    points along increasing longitude (east), the seam duplicated so that UVs do not wrap."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    normals = np.stack([np.sin(th) * np.sin(ph), np.cos(th), np.sin(th) * np.cos(ph)], axis=-1)
    tangents = np.stack([np.cos(ph), np.zeros_like(ph), -np.sin(ph)], axis=-1)  # d normal / d phi, normalised
    uvs = np.stack([ph / (2.0 * np.pi), 1.0 - th / np.pi], axis=-1)
    return grid_mesh(normals * radius, normals, tangents, uvs)


def vertex_tangents(positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Per-vertex tangents along increasing u (Lengyel's method): each triangle's dP/du from its edges and
    their UV differences, summed over the triangles at a vertex (larger triangles weigh more), then made
    orthogonal to the vertex normal. Where the UVs give no direction (degenerate or missing), any unit
    vector orthogonal to the normal."""
    p, t = positions[indices].astype(np.float64), uvs[indices].astype(np.float64)  # (T, 3, 3), (T, 3, 2)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    sign = np.where(det < 0, -1.0, 1.0)  # mirrored UVs: keep the direction of increasing u
    face = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * sign[:, None]  # dP/du scaled by |det|: area weighting
    tangent = np.zeros_like(positions, dtype=np.float64)
    for corner in range(3):
        np.add.at(tangent, indices[:, corner], face)
    n = normals.astype(np.float64)
    tangent -= n * np.sum(tangent * n, axis=1, keepdims=True)
    length = np.linalg.norm(tangent, axis=1, keepdims=True)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    fallback = np.cross(n, helper)
    fallback /= np.maximum(np.linalg.norm(fallback, axis=1, keepdims=True), 1e-12)
    return np.where(length > 1e-12, tangent / np.maximum(length, 1e-12), fallback).astype(np.float32)


MESH_FORMATS = "OBJ, PLY, STL, OFF or glTF"


def load_mesh(path: Path) -> tuple[Mesh, bool]:
    """A triangle mesh from a file (trimesh reads it; vertices split where their UVs differ) and whether
    it has texture coordinates; both UV sets are the file's (zeros without them), tangents per vertex."""
    import trimesh

    try:
        mesh = trimesh.load(str(path), process=False)  # (force="mesh" would drop the file's normals)
        if isinstance(mesh, trimesh.Scene):  # several parts: one mesh, each part placed by its transform
            mesh = mesh.to_mesh()
    except Exception as exc:  # trimesh raises what its parsers raise: ValueError, KeyError, IndexError, ...
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ArsimError(f"{path}: cannot read the mesh ({reason}); give an {MESH_FORMATS} file of triangles") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ArsimError(f"{path}: no triangles in the mesh; give an {MESH_FORMATS} file of triangles")
    positions = np.asarray(mesh.vertices, dtype=np.float64)
    if not np.isfinite(positions).all():
        raise ArsimError(f"{path}: the mesh has vertices that are not finite numbers; fix the file")
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
    uv = getattr(mesh.visual, "uv", None)
    textured = uv is not None and len(uv) == len(positions) and np.isfinite(uv).all()
    uvs = np.asarray(uv, dtype=np.float64) if textured else np.zeros((len(positions), 2))
    indices = np.asarray(mesh.faces, dtype=np.uint32)
    tangents = vertex_tangents(positions, normals, uvs, indices)
    f32 = (lambda x: np.ascontiguousarray(x, dtype=np.float32))
    return Mesh(f32(positions), f32(normals), tangents, f32(uvs), f32(uvs), indices), textured
