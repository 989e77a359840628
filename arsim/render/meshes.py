"""Meshes of the virtual objects: positions, normals, per-vertex tangents, two UV sets (normal map and
light map) and triangle indices, in object space (y up)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
