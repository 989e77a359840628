"""Precomputed radiance transfer with normal maps (the normal-mapping-prt spec; Sloan 2002, 2003): what a
point of a rigid object receives of a distant light, shadows by the scene included, precomputed once and
relit every frame from the light's SH coefficients.

Frames and bases (README: Precomputed radiance transfer):
- The distant light l: real SH of `order` bands (0 .. order-1), orthonormal over the sphere, no
  Condon-Shortley phase, index l(l+1)+m, in world axes with the pole along world +z (`sh_basis`; its first
  nine are `bases.functions.sh9`). Coefficients (order^2, 3) of radiance.
- The transfer matrix M of a point (a vertex or a light-map texel): the incident radiance that reaches it,
  visibility applied, as quadratic SH (bands 0-2) in its tangent frame (x the tangent, y the bitangent
  n x t, z the normal): c = M l, (9, 3). The spec's R (world to the local frame) is folded into M, since
  the object is rigid; an object turned by Q sees the light D(Q^-1) l (`sh_rotation`).
- Exit radiance (eq. 3.1): E(n) = y(n)^T C c at the normal map's normal n in tangent space, C the clamped
  cosine's convolution; E / pi is the diffuse term (what an irradiance map holds).

The spec's four evaluations are `VARIANTS`, each a basis over the hemisphere of tangent-space normals and a
(count, 9) projection P from c: the per-point coefficients P M l (folded into one (count, order^2) matrix
per point, so that relighting is one product), and the basis evaluated per pixel at the normal.
"""

from __future__ import annotations

import hashlib
import io
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache, lru_cache
from math import sqrt
from pathlib import Path

import numpy as np
import scipy.sparse
import scipy.special

from arsim.core.errors import ArsimError
from arsim.core.files import user_cache_dir, write_bytes_atomic
from arsim.lighting.bases.functions import get_basis, sh9
from arsim.lighting.bases.irradiance import COSINE_KERNEL
from arsim.lighting.bases.projection import from_sh9_matrix
from arsim.lighting.bases.quadrature import sphere_quadrature

MIN_ORDER, MAX_ORDER = 3, 10  # bands of the light: at least the quadratic ones the variants need
DEFAULT_ORDER = 5  # bands 0-4
SEP_GRID = 32  # the separable basis's normals: 32 x 32 on the unit square (spec 3.2)
SEP_TEXTURE = 64  # its U columns resampled by the normal's orthographic projection (64 x 64)
SEP_TERMS = 4  # singular values kept (the spec's M)


# ----------------------------------------------------------------------------------------------------
# SH of any order, and their rotations


def sh_basis(directions: np.ndarray, order: int) -> np.ndarray:
    """(..., order^2): the real orthonormal SH of bands 0 .. order-1 at unit directions (..., 3), no
    Condon-Shortley phase, index l(l+1)+m, pole +z (y_l^m ~ cos(m phi) for m > 0, sin(|m| phi) for m < 0)."""
    d = np.asarray(directions, dtype=np.float64)
    theta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))[..., None]
    phi = np.arctan2(d[..., 1], d[..., 0])[..., None]
    ls = np.repeat(np.arange(order), 2 * np.arange(order) + 1)
    ms = np.concatenate([np.arange(-l, l + 1) for l in range(order)])
    y = scipy.special.sph_harm_y(ls, np.abs(ms), theta, phi)  # complex, with the Condon-Shortley phase
    sign = np.where(ms % 2 == 1, -1.0, 1.0) * np.sqrt(2.0)  # (-1)^m undoes the phase
    return np.where(ms > 0, sign * y.real, np.where(ms < 0, sign * y.imag, y.real))


@cache
def _rotation_rule(order: int) -> tuple[np.ndarray, np.ndarray]:
    # exact for the products of two SH of bands < order (degree 2 order - 2): Gauss in z, uniform in phi
    return sphere_quadrature(order + 1, 2 * order + 1)


def sh_rotation(rotation: np.ndarray, order: int) -> np.ndarray:
    """(order^2, order^2) D with D l the SH of the light turned by the 3 x 3 rotation (L'(w) = L(R^T w)),
    by projection with a rule exact for band-limited products (block-diagonal by band)."""
    d, w = _rotation_rule(order)
    r = np.asarray(rotation, dtype=np.float64)
    return (sh_basis(d, order) * w[:, None]).T @ sh_basis(d @ r, order)  # (d @ r: R^T d per row)


# ----------------------------------------------------------------------------------------------------
# Transfer


Blocked = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (origins (T, 3), directions (K, T, 3)) -> (K, T) bool


@dataclass(frozen=True)
class Transfer:
    """Per point (P points): the transfer matrices (P, 9, order^2) into tangent-space quadratic SH, and the
    diffuse transfer vectors (P, order^2) of the spec's "PRT" row, E = t . l, with and without shadows."""

    matrices: np.ndarray
    shadowed: np.ndarray
    unshadowed: np.ndarray
    order: int

    def relight(self, light: np.ndarray) -> np.ndarray:
        """(P, 9, 3): the incident radiance's quadratic SH in each point's frame, c = M l."""
        return self.matrices @ light


def transfer_rule(samples: int) -> tuple[np.ndarray, np.ndarray]:
    """About `samples` directions over the sphere and their weights: Gauss in the height, uniform in the
    azimuth (1 : 2), the pole along world +y (up), so that the rule resolves elevation above the table and
    a turn about the vertical by a multiple of its azimuth step maps it onto itself."""
    n_z = max(int(round(sqrt(samples / 2))), 4)
    d, w = sphere_quadrature(n_z, 2 * n_z)
    return d[:, [1, 2, 0]], w  # (x, y, z) <- (y, z, x): the rule's pole to +y


def local_sh9_rotation(tangents: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(P, 9, 9) R with sh9(F w) = R sh9(w), F the world-to-tangent rotation (rows t, n x t, n)."""
    frames = np.stack([tangents, np.cross(normals, tangents), normals], axis=1)
    d, w = _rotation_rule(3)
    local = np.einsum("pij,kj->pki", frames, d)  # F d per point
    return np.einsum("pks,kr->psr", sh9(local) * w[None, :, None], sh9(d))


# The light a hit point sends back along a ray, as a transfer vector (N, order^2) of the distant light:
# bounce(hit points (N, 3), ray directions (N, 3)) = albedo / pi x the shadowed diffuse transfer there.
Bounce = Callable[[np.ndarray, np.ndarray], np.ndarray]


def compute_transfer(points: np.ndarray, normals: np.ndarray, tangents: np.ndarray, order: int = DEFAULT_ORDER,
                     blocked: Blocked | None = None, samples: int = 2048, chunk: int = 256,
                     progress: Callable[[int], None] | None = None, distance: Blocked | None = None,
                     bounce: Bounce | None = None) -> Transfer:
    """Transfer of points (P, 3) with unit normals and tangents (P, 3): the light arriving from each of
    about `samples` directions, dropped below the point's tangent plane (the surface hides it) and where
    blocked(...) says a ray hits the scene; integrated against the light's SH (world) and the local
    quadratic SH. With bounce (and distance(...), how far each ray's hit is, inf for none, in place of
    blocked), one bounce of interreflection (Sloan 2002): a ray that hits the scene brings what its hit
    point sends back, bounce(hit, direction). progress(n) is called with the points done."""
    check_order(order)
    if bounce is not None:
        chunk = min(chunk, 64)  # (the hits' transfer vectors are held per chunk)
    points, normals, tangents = (np.asarray(a, dtype=np.float64).reshape(-1, 3) for a in (points, normals, tangents))
    d, w = transfer_rule(samples)
    ylight = sh_basis(d, order) * w[:, None]  # (K, L2), weighted
    y9 = sh9(d)  # (K, 9) world quadratic SH
    products = (y9[:, :, None] * ylight[:, None, :]).reshape(len(d), -1)  # (K, 9 L2): one GEMM per chunk below
    rotations = local_sh9_rotation(tangents, normals)
    n, l2 = len(points), order * order
    matrices, shadowed, unshadowed = np.empty((n, 9, l2)), np.empty((n, l2)), np.empty((n, l2))
    for start in range(0, n, chunk):
        sl = slice(start, min(start + chunk, n))
        cosine = normals[sl] @ d.T  # (T, K)
        visible = (cosine > 0).astype(np.float64)
        unshadowed[sl] = np.maximum(cosine, 0.0) @ ylight
        rays = np.broadcast_to(d[:, None, :], (len(d), sl.stop - sl.start, 3))
        if bounce is not None:
            far = distance(points[sl], rays).T  # (T, K)
            hit = np.isfinite(far) & (visible > 0)
            visible *= ~hit
        elif blocked is not None:
            visible *= ~blocked(points[sl], rays).T
        shadowed[sl] = (np.maximum(cosine, 0.0) * visible) @ ylight
        world = (visible @ products).reshape(-1, 9, l2)  # the visible light's quadratic SH, world axes
        if bounce is not None and hit.any():
            t, k = np.nonzero(hit)
            sent = bounce(points[sl][t] + d[k] * far[t, k][:, None], d[k])  # (N, L2), the light's SH -> radiance
            # per point, the sum over its hit rays: scatter by point with a sparse (T x N) sum
            gather = scipy.sparse.csr_matrix((np.ones(len(t)), (t, np.arange(len(t)))), shape=(sl.stop - sl.start, len(t)))
            shadowed[sl] += gather @ (sent * (np.maximum(cosine[t, k], 0.0) * w[k])[:, None])
            world += (gather @ ((y9[k] * w[k][:, None])[:, :, None] * sent[:, None, :]).reshape(len(t), -1)).reshape(-1, 9, l2)
        matrices[sl] = rotations[sl] @ world
        if progress is not None:
            progress(sl.stop - sl.start)
    return Transfer(matrices, shadowed, unshadowed, order)


def check_order(order: int) -> None:
    if not (isinstance(order, (int, np.integer)) and MIN_ORDER <= order <= MAX_ORDER):
        raise ArsimError(f"PRT order {order}: give {MIN_ORDER} to {MAX_ORDER} bands of the light's SH "
                         f"(the variants need the quadratic bands 0-2; {DEFAULT_ORDER} is the default)")


# ----------------------------------------------------------------------------------------------------
# The spec's variants: a basis over tangent-space normals and a projection from c (9) to its coefficients


def _concentric_to_disk(s: np.ndarray) -> np.ndarray:
    """Shirley and Chiu's concentric map: points of [0, 1]^2 (..., 2) to the unit disk."""
    a, b = 2 * s[..., 0] - 1, 2 * s[..., 1] - 1
    first = np.abs(a) > np.abs(b)
    safe_a, safe_b = np.where(a == 0, 1.0, a), np.where(b == 0, 1.0, b)
    r = np.where(first, a, b)
    phi = np.where(first, np.pi / 4 * b / safe_a, np.pi / 2 - np.pi / 4 * a / safe_b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def _disk_to_concentric(p: np.ndarray) -> np.ndarray:
    """The inverse of _concentric_to_disk."""
    x, y = p[..., 0], p[..., 1]
    r = np.hypot(x, y)
    phi = np.arctan2(y, x)  # (-pi, pi]
    phi = np.where(phi < -np.pi / 4, phi + 2 * np.pi, phi)  # [-pi/4, 7 pi/4)
    sector = np.floor((phi + np.pi / 4) / (np.pi / 2)).astype(int) % 4
    t = phi - sector * np.pi / 2  # in [-pi/4, pi/4)
    u = r * 4 / np.pi * t  # the coordinate along the square's side
    a = np.select([sector == 0, sector == 1, sector == 2], [r, -u, -r], u)
    b = np.select([sector == 0, sector == 1, sector == 2], [u, r, -u], -r)
    return np.stack([(a + 1) / 2, (b + 1) / 2], axis=-1)


def square_to_hemisphere(s: np.ndarray) -> np.ndarray:
    """Points of the unit square (..., 2) to unit directions with z >= 0: Shirley and Chiu's concentric
    disk, lifted by the equal-area map (z = 1 - r^2), so that equal squares hold equal solid angles."""
    p = _concentric_to_disk(s)
    r2 = np.sum(p * p, axis=-1)
    scale = np.sqrt(np.clip(2 - r2, 0.0, None))
    return np.stack([p[..., 0] * scale, p[..., 1] * scale, 1 - r2], axis=-1)


def hemisphere_to_square(d: np.ndarray) -> np.ndarray:
    """The inverse of square_to_hemisphere for unit directions (..., 3) (z < 0 taken at the horizon)."""
    d = np.asarray(d, dtype=np.float64)
    z = np.clip(d[..., 2], 0.0, 1.0)
    horizontal = np.maximum(np.hypot(d[..., 0], d[..., 1]), 1e-300)
    r = np.sqrt(1 - z)  # equal-area: z = 1 - r^2
    p = d[..., :2] / horizontal[..., None] * r[..., None]
    return _disk_to_concentric(p)


def _bilinear(grid: np.ndarray, s: np.ndarray) -> np.ndarray:
    """grid (N, N, C) sampled at texel centres (i + 0.5) / N, at points (..., 2) of [0, 1]^2 (s[..., 0]
    along the second axis), bilinear and clamped to the edge texels, as a GL texture with CLAMP_TO_EDGE."""
    n = grid.shape[0]
    p = np.clip(s * n - 0.5, 0.0, n - 1.0)
    i0 = np.minimum(np.floor(p).astype(int), n - 2)
    a = p - i0
    x0, y0 = i0[..., 0], i0[..., 1]
    ax, ay = a[..., 0:1], a[..., 1:2]
    return ((1 - ay) * ((1 - ax) * grid[y0, x0] + ax * grid[y0, x0 + 1])
            + ay * ((1 - ax) * grid[y0 + 1, x0] + ax * grid[y0 + 1, x0 + 1]))


@dataclass(frozen=True)
class Separable:
    """The separable basis (spec 3.2): the SVD A = U S V of the 1024 x 9 matrix A of quadratic SH (times C
    when `absorbed`) at the 32 x 32 square's normals; U's first `terms` columns resampled into a 64 x 64
    texture indexed by the normal's orthographic projection (x, y) -> ((x, y) + 1) / 2."""

    absorbed: bool
    terms: int
    singular: np.ndarray  # (9,) all of S, for the error of the truncation
    projection: np.ndarray  # (terms, 9): S_m V_m (C), from c to the coefficients
    texture: np.ndarray  # (64, 64, terms) float32, row 0 at y = -1 (GL's first row)

    def evaluate(self, normals: np.ndarray) -> np.ndarray:
        """(..., terms): the texture's bilinear value at the normals' orthographic projections."""
        n = np.asarray(normals, dtype=np.float64)
        return _bilinear(self.texture.astype(np.float64), (n[..., :2] + 1) / 2)


@cache
def separable(absorbed: bool = False, terms: int = SEP_TERMS) -> Separable:
    centres = (np.arange(SEP_GRID) + 0.5) / SEP_GRID
    square = np.stack(np.meshgrid(centres, centres, indexing="xy"), axis=-1)  # [row, col] -> (s along col, t along row)
    a = sh9(square_to_hemisphere(square)).reshape(-1, 9)
    if absorbed:
        a = a * COSINE_KERNEL
    u, s, vt = np.linalg.svd(a, full_matrices=False)
    sign = np.where(u.sum(axis=0) < 0, -1.0, 1.0)  # (the SVD's signs are arbitrary: each column sums >= 0)
    u, vt = u * sign, vt * sign[:, None]
    u_grid = u[:, :terms].reshape(SEP_GRID, SEP_GRID, terms)
    # The 64 x 64 texture: each texel centre (x, y) in [-1, 1]^2 lifted to the hemisphere (outside the unit
    # disk, the rim), then to the square, where U is interpolated bilinearly between the grid's samples.
    xy = (np.arange(SEP_TEXTURE) + 0.5) / SEP_TEXTURE * 2 - 1
    x, y = np.meshgrid(xy, xy, indexing="xy")
    rho = np.hypot(x, y)
    shrink = np.where(rho > 1, 1 / np.maximum(rho, 1e-12), 1.0)
    x, y = x * shrink, y * shrink
    z = np.sqrt(np.clip(1 - x * x - y * y, 0.0, None))
    texture = _bilinear(u_grid, hemisphere_to_square(np.stack([x, y, z], axis=-1)))
    projection = s[:terms, None] * vt[:terms]
    if not absorbed:
        projection = projection * COSINE_KERNEL
    return Separable(absorbed, terms, s, projection, texture.astype(np.float32))


@dataclass(frozen=True)
class Variant:
    """One of the spec's evaluations: its basis (a bases.functions name and count, or the separable one),
    the (count, 9) projection from the incident radiance's quadratic SH c to the basis's coefficients."""

    name: str
    label: str
    count: int
    projection: np.ndarray = field(repr=False)
    basis: str = ""  # a bases.functions name ("sh", "hl2", "hsh"); "" for the separable basis
    separable: Separable | None = field(default=None, repr=False)

    def evaluate(self, normals: np.ndarray) -> np.ndarray:
        """(..., count): the basis at unit tangent-space normals."""
        if self.separable is not None:
            return self.separable.evaluate(normals)
        return get_basis(self.basis).evaluate(normals, self.count)


@cache
def get_variant(name: str) -> Variant:
    """The variant of that name: gs, sep, sep-c, hl2 or sal; another raises ArsimError listing them."""
    cosine = np.diag(COSINE_KERNEL)
    if name == "gs":
        return Variant("gs", "gold standard: quadratic SH at the normal (eq. 3.1)", 9, cosine, "sh")
    if name in ("sep", "sep-c"):
        sep = separable(absorbed=name == "sep-c")
        label = "separable, " + ("C absorbed into A" if sep.absorbed else "C applied after") + f", {sep.terms} terms (eq. 3.3)"
        return Variant(name, label, sep.terms, sep.projection, separable=sep)
    if name == "hl2":
        return Variant("hl2", "Half-Life 2 basis, unclamped", 3, from_sh9_matrix(get_basis("hl2"), 3) @ cosine, "hl2")
    if name == "sal":
        return Variant("sal", "shifted associated Legendre (HSH), 4 terms", 4, from_sh9_matrix(get_basis("hsh"), 4) @ cosine, "hsh")
    raise ArsimError(f"unknown PRT variant '{name}'; use one of {', '.join(VARIANTS)}")


VARIANTS = ("gs", "sep", "sep-c", "hl2", "sal")


def light_sh(anglemap: np.ndarray, order: int = DEFAULT_ORDER) -> np.ndarray:
    """(order^2, 3): the SH (world axes, sh_basis) of an angle-map light, by the sum over its disk texels
    with their solid angles."""
    from arsim.lighting.bases.lightmap import probe_samples

    check_order(order)
    anglemap = np.asarray(anglemap)
    _, weighted = probe_samples(anglemap)
    return _anglemap_basis(anglemap.shape[0], order).T @ weighted


@lru_cache(maxsize=4)
def _anglemap_basis(n: int, order: int) -> np.ndarray:
    """(disk texels, order^2): the SH at an n x n angle map's disk texels (kept: relighting reads it per frame)."""
    from arsim.lighting.bases.lightmap import probe_samples

    directions, _ = probe_samples(np.zeros((n, n, 3), np.float32))
    return sh_basis(directions, order)


def variant_transfer(transfer: Transfer, variant: Variant) -> np.ndarray:
    """(P, count, order^2): the variant's per-point matrices P M, so that relighting is one product."""
    return np.einsum("bs,psl->pbl", variant.projection, transfer.matrices).astype(np.float32)


def relight(matrices: np.ndarray, light: np.ndarray) -> np.ndarray:
    """(P, count, 3) coefficients of each point from its (P, count, order^2) matrices and the light
    (order^2, 3): one matrix product, in float32."""
    p, count, l2 = matrices.shape
    return (matrices.reshape(p * count, l2) @ np.asarray(light, dtype=np.float32)).reshape(p, count, 3)


def prt_diffuse(coefficients: np.ndarray, variant: Variant, normal_tangent: np.ndarray) -> np.ndarray:
    """E / pi (..., 3) at tangent-space normals (..., 3) from a point's coefficients (..., count, 3)."""
    n = np.asarray(normal_tangent, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    return np.einsum("...k,...kc->...c", variant.evaluate(n), np.asarray(coefficients, dtype=np.float64)) / np.pi


# ----------------------------------------------------------------------------------------------------
# CPCA (Sloan 2003): the per-point matrices clustered, each cluster a mean and a few principal vectors


@dataclass(frozen=True)
class Compressed:
    """Per cluster a mean (count, order^2) and `vectors` principal matrices; per point its cluster and
    weights. Relighting: per cluster (1 + vectors) products with the light, then per point a weighted sum."""

    means: np.ndarray  # (clusters, count, L2)
    vectors: np.ndarray  # (clusters, N, count, L2)
    labels: np.ndarray  # (P,)
    weights: np.ndarray  # (P, N) float32

    def cluster_coefficients(self, light: np.ndarray) -> np.ndarray:
        """(clusters, 1 + N, count, 3): each cluster's mean and principal matrices times the light, all a
        frame computes on the CPU where the GPU sums them per vertex (the renderer's PRT_CPCA)."""
        stacked = np.concatenate([self.means[:, None], self.vectors], axis=1).astype(np.float32)
        c, n1, count, l2 = stacked.shape
        return (stacked.reshape(-1, l2) @ np.asarray(light, dtype=np.float32)).reshape(c, n1, count, 3)

    def relight(self, light: np.ndarray) -> np.ndarray:
        """(P, count, 3): every point's coefficients (the per-point sum done here; the reference of the GPU's)."""
        per = self.cluster_coefficients(light)[self.labels]  # (P, 1 + N, count, 3)
        return per[:, 0] + np.einsum("pn,pnkc->pkc", self.weights, per[:, 1:], optimize=True)

    def matrices(self) -> np.ndarray:
        """(P, count, L2) the matrices as compressed (for the error)."""
        return self.means[self.labels] + np.einsum("pn,pnkl->pkl", self.weights, self.vectors[self.labels])


def compress(matrices: np.ndarray, clusters: int = 64, vectors: int = 4, seed: int = 0, rounds: int = 4) -> Compressed:
    """CPCA of (P, count, L2) matrices: k-means on the flattened matrices (SciPy), then within each cluster
    the principal vectors of the points' differences from its mean (SVD); a few rounds of reassigning
    each point to the cluster whose mean and vectors reconstruct it best (Sloan 2003's iteration)."""
    from scipy.cluster.vq import kmeans2

    p, count, l2 = matrices.shape
    flat = matrices.reshape(p, -1).astype(np.float64)
    clusters = max(1, min(clusters, p))
    with warnings.catch_warnings():  # (a cluster left empty is refilled by the reassignment below)
        warnings.simplefilter("ignore", UserWarning)
        _, labels = kmeans2(flat, clusters, minit="points", seed=seed)  # (SciPy's "++" start takes minutes here)
    dim = flat.shape[1]
    vectors = min(vectors, dim)
    squared = np.sum(flat * flat, axis=1)
    for _ in range(rounds):
        means = np.zeros((clusters, dim))
        bases = np.zeros((clusters, vectors, dim))
        for k in range(clusters):
            members = flat[labels == k]
            if not len(members):
                continue
            means[k] = members.mean(axis=0)
            _, _, vt = np.linalg.svd(members - means[k], full_matrices=False)
            bases[k, :len(vt[:vectors])] = vt[:vectors]
        # every point's reconstruction error under every cluster, |x - m|^2 - |B (x - m)|^2, by two products
        # over all clusters at once (the basis rows orthonormal); each point to its best cluster
        along_mean = flat @ means.T  # (P, K)
        projected = (flat @ bases.reshape(-1, dim).T).reshape(p, clusters, vectors)
        projected -= np.einsum("knd,kd->kn", bases, means)[None]
        errors = squared[:, None] - 2 * along_mean + np.sum(means * means, axis=1)[None] - np.sum(projected ** 2, axis=2)
        labels = np.argmin(errors, axis=1)
    weights = np.einsum("pd,pnd->pn", flat - means[labels], bases[labels])
    return Compressed(means.reshape(clusters, count, l2), bases.reshape(clusters, vectors, count, l2), labels,
                      weights.astype(np.float32))


# ----------------------------------------------------------------------------------------------------
# The cache on disk


def cache_folder() -> Path | None:
    """Where transfers are kept: prt/ in arsim's cache folder (core.files.user_cache_dir); None where
    $ARSIM_CACHE is off (computed every time)."""
    root = user_cache_dir()
    return None if root is None else root / "prt"


def transfer_key(*parts) -> str:
    """A key for the cache from the arrays and settings that determine a transfer."""
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(str((part.dtype, part.shape)).encode())
            h.update(np.ascontiguousarray(part).tobytes())
        else:
            h.update(repr(part).encode())
    return h.hexdigest()[:32]


def cached_transfer(key: str, compute: Callable[[], Transfer]) -> Transfer:
    """The transfer kept under key, or computed and kept (atomically; an unwritable cache only costs time)."""
    folder = cache_folder()
    if folder is None:
        return compute()
    path = folder / f"{key}.npz"
    if path.is_file():
        try:
            with np.load(path) as f:
                return Transfer(f["matrices"], f["shadowed"], f["unshadowed"], int(f["order"]))
        except (OSError, ValueError, KeyError):
            pass  # a damaged entry: computed again and replaced
    transfer = compute()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        buffer = io.BytesIO()
        np.savez(buffer, matrices=transfer.matrices, shadowed=transfer.shadowed, unshadowed=transfer.unshadowed,
                 order=transfer.order)
        write_bytes_atomic(path, buffer.getvalue())
    except (OSError, ArsimError):
        pass
    return transfer
