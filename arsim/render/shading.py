"""NumPy reference of the renderer's shading (thesis Alg. 5.1, 5.2, 5.4) and tone mapping (Alg. 5.5):
the oracle the GL path is tested against.

Vectors are world-space arrays (..., 3); maps are angle maps (N, N, 3) looked up bilinearly with the
texels outside the disk extended from the rim, as the GL textures are (core.resample.sample_anglemap).
"""

from __future__ import annotations

import numpy as np

from arsim.core.conventions import normalize
from arsim.core.resample import sample_anglemap

# Thesis Alg. 5.5 line 3: the luminance weights of the tone mapper (Rec. 601).
TONEMAP_LUMA = np.array([0.299, 0.587, 0.114])
LOG_DELTA = 1e-4  # Reinhard's small delta inside the log-average (log 0 on black pixels)


def reflect(incident: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """GLSL's reflect(I, N) = I - 2 (N . I) N, with I pointing from the eye to the surface."""
    return incident - 2.0 * np.sum(normal * incident, axis=-1, keepdims=True) * normal


def perturbed_normal(normal: np.ndarray, tangent: np.ndarray, texel: np.ndarray) -> np.ndarray:
    """Alg. 5.4 lines 2-8: a tangent-space normal-map texel (..., 3) in [0, 1] (eq. 5.2 maps it to
    [-1, 1]) turned into world space by the frame (t, n x t, n) of the interpolated vectors."""
    n_t = 2.0 * np.asarray(texel, dtype=np.float64) - 1.0
    n, t = normalize(normal), normalize(tangent)
    b = np.cross(n, t)
    return normalize(t * n_t[..., :1] + b * n_t[..., 1:2] + n * n_t[..., 2:3])


def shade(normal: np.ndarray, incident: np.ndarray, irradiance: np.ndarray, reflection: np.ndarray,
          kd: np.ndarray, ks: np.ndarray, light: np.ndarray | None = None) -> np.ndarray:
    """Alg. 5.1 (and 5.2 with a light-map value `light`): L_o = k_d M_1(n) [x light] + k_s M_s(reflect(v, n)).

    Alg. 5.4 line 9 looks the irradiance up with the unperturbed normal n_w; that is a typo for the
    perturbed n (the text: "only the normal has been modified by normal mapping"), which is used here."""
    n = normalize(normal)
    diffuse = sample_anglemap(irradiance, n)
    if light is not None:
        diffuse = diffuse * light
    specular = sample_anglemap(reflection, reflect(normalize(incident), n))
    return np.asarray(kd) * diffuse + np.asarray(ks) * specular


def cube_texel_seamless(level: np.ndarray, face: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Texels (K, C) of a cube level (6, N, N, C) at integer (face, row, col) that may lie one texel past the
    face's edge, as GL's seamless cube maps read them: past an edge, the adjacent face's texel there (the
    one the direction through the texel's centre, on the face's plane extended, falls in); past a corner,
    the mean of the three texels that meet there."""
    from arsim.core.conventions import CUBE_FACES, cube_texels

    n = level.shape[1]
    inside_r, inside_c = (row >= 0) & (row < n), (col >= 0) & (col < n)
    table = np.array(CUBE_FACES, dtype=np.float64)

    def across(r, c):  # the texel the extended texel's centre direction falls in
        s, t = (c + 0.5) / n * 2 - 1, (r + 0.5) / n * 2 - 1
        d = table[face, 0] + s[:, None] * table[face, 1] + t[:, None] * table[face, 2]
        f, rr, cc = cube_texels(normalize(d), n)
        return level[f, rr, cc]

    rc, cc = np.clip(row, 0, n - 1), np.clip(col, 0, n - 1)
    out = level[face, rc, cc].astype(np.float64)
    edge_c, edge_r = inside_r & ~inside_c, ~inside_r & inside_c
    out[edge_c | edge_r] = across(row, col)[edge_c | edge_r]
    corner = ~inside_r & ~inside_c
    if corner.any():
        out[corner] = (level[face, rc, cc] + across(rc, col) + across(row, cc))[corner] / 3.0
    return out


def sample_cube_seamless(level: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Bilinear values (K, C) of a cube level (6, N, N, C) in unit directions (K, 3), across the faces' edges
    as GL's seamless cube-map filtering (cube_texel_seamless)."""
    from arsim.core.conventions import cube_face_st

    n = level.shape[1]
    face, s, t = cube_face_st(directions)
    x, y = (s + 1.0) * 0.5 * n - 0.5, (t + 1.0) * 0.5 * n - 0.5
    c0, r0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - c0)[:, None], (y - r0)[:, None]
    texel = lambda dr, dc: cube_texel_seamless(level, face, r0 + dr, c0 + dc)  # noqa: E731
    return (1 - fy) * ((1 - fx) * texel(0, 0) + fx * texel(0, 1)) + fy * ((1 - fx) * texel(1, 0) + fx * texel(1, 1))


def sample_cube_chain(chain, directions: np.ndarray, lod: np.ndarray) -> np.ndarray:
    """textureLod on a cube map with mip levels (LINEAR_MIPMAP_LINEAR, seamless): bilinear in the two levels
    around each lod (K,), clamped to the chain, and linear between them."""
    lod = np.clip(np.asarray(lod, dtype=np.float64), 0.0, len(chain) - 1)
    lower = np.minimum(np.floor(lod).astype(int), len(chain) - 1)
    frac = (lod - lower)[:, None]
    out = np.zeros((len(directions), chain[0].shape[-1]))
    for p in np.unique(lower):
        sel = lower == p
        value = (1.0 - frac[sel]) * sample_cube_seamless(chain[p], directions[sel])
        if p + 1 < len(chain):
            value += frac[sel] * sample_cube_seamless(chain[p + 1], directions[sel])
        out[sel] = value
    return out


def sample_lut(lut: np.ndarray, n_dot_v: np.ndarray, roughness: np.ndarray) -> np.ndarray:
    """(K, 2) the split sum's (A, B) from the table (S, S, 2) (lighting.ggx.brdf_lut: n.v across, roughness
    down) at (n.v, roughness), bilinear between texel centres and clamped to the edge texels, as GL."""
    size_r, size_c = lut.shape[:2]
    x = np.clip(np.asarray(n_dot_v, dtype=np.float64) * size_c - 0.5, 0.0, size_c - 1.0)
    y = np.clip(np.asarray(roughness, dtype=np.float64) * size_r - 0.5, 0.0, size_r - 1.0)
    c0, r0 = np.floor(x).astype(int), np.floor(y).astype(int)
    c1, r1 = np.minimum(c0 + 1, size_c - 1), np.minimum(r0 + 1, size_r - 1)
    fx, fy = (x - c0)[:, None], (y - r0)[:, None]
    return (1 - fy) * ((1 - fx) * lut[r0, c0] + fx * lut[r0, c1]) + fy * ((1 - fx) * lut[r1, c0] + fx * lut[r1, c1])


def shade_ggx(normal: np.ndarray, incident: np.ndarray, irradiance: np.ndarray, chain, lut: np.ndarray,
              base_color, metallic: float, roughness: float, light: np.ndarray | None = None) -> np.ndarray:
    """A GGX metallic-roughness material lit with the split sum, on (K, 3) normals and incident vectors:
    L_o = (1 - metallic) base_color M_1(n) [x light] + P(reflect(v, n), roughness) (F0 A + B), with M_1 the
    irradiance angle map (E / pi), P the prefiltered cube chain (lighting.ggx.prefilter_ggx) read at level
    roughness (levels - 1), F0 = mix(0.04, base_color, metallic) and (A, B) the table (lighting.ggx.brdf_lut)
    at (n.v, roughness)."""
    n, v = normalize(normal), normalize(incident)
    diffuse = sample_anglemap(irradiance, n)
    if light is not None:
        diffuse = diffuse * light
    base = np.asarray(base_color, dtype=np.float64)
    n_dot_v = np.clip(-np.sum(n * v, axis=-1), 0.0, 1.0)
    rough = np.full(len(n), float(roughness))
    split = sample_lut(lut, n_dot_v, rough)
    prefiltered = sample_cube_chain(chain, reflect(v, n), rough * (len(chain) - 1))
    f0 = 0.04 * (1.0 - metallic) + base * metallic
    return (1.0 - metallic) * base * diffuse + prefiltered * (f0 * split[:, :1] + split[:, 1:])


def inm_diffuse(coefficients: np.ndarray, basis: str, normal_tangent: np.ndarray, terms: int | None = None) -> np.ndarray:
    """Irradiance normal mapping's diffuse term, E / pi (what an irradiance map holds): the basis (e.g.
    "modh6") at the tangent-space normals (..., 3) weighted by the light map's coefficients there
    (..., count, 3), the first `terms` of them (the spec's level of detail; None: all)."""
    from arsim.lighting.bases import parse_basis

    b, count = parse_basis(basis)
    values = b.evaluate(normalize(normal_tangent), count)[..., :terms]
    return np.einsum("...k,...kc->...c", values, np.asarray(coefficients)[..., :terms, :]) / np.pi


def volume_diffuse(volume: tuple, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """An irradiance volume's diffuse term, E / pi, at world points and normals (..., 3): the coefficients
    interpolated trilinearly (clamped at the box's faces), SH bands 0-2 at the normal."""
    from arsim.lighting.bases.lightmap import sample_volume, volume_irradiance

    coefficients, low, high = volume
    return volume_irradiance(sample_volume(np.asarray(coefficients), np.asarray(low), np.asarray(high), points),
                             normalize(normals)) / np.pi


def average_luminance(hdr: np.ndarray, mask: np.ndarray, log_average: bool = False) -> float:
    """The scene's average luminance over the masked pixels: their mean, what the top of a mip chain
    gives (thesis 5.3.4; the renderer sums blocks instead, to the same value), or Reinhard's log-average
    exp(mean(log(delta + L_w)))."""
    luminance = hdr[..., :3] @ TONEMAP_LUMA
    inside = np.asarray(mask) > 0.5
    if not inside.any():
        return 1.0
    if log_average:
        return float(np.exp(np.mean(np.log(LOG_DELTA + luminance[inside]))))
    return float(luminance[inside].mean())


def tonemap(hdr: np.ndarray, mask: np.ndarray, key: float, white: float, average: float) -> np.ndarray:
    """Alg. 5.5: Reinhard's eq. 5.5 on the scaled luminance L = key L_w / average, applied where the mask
    is 1, the colour scaled by L_d / L_w; elsewhere the colour passes unchanged.

    Line 9 returns C_w (1 + (L_d - 1) m), which multiplies the HDR colour by L_d; what it plainly means,
    and what Reinhard's operator does, is to scale the colour so that its luminance becomes L_d:
    C_w L_d / L_w (here, with L_w = 0 giving black)."""
    colour = np.asarray(hdr, dtype=np.float64)[..., :3]
    lw = colour @ TONEMAP_LUMA
    scaled = key * lw / average
    ld = scaled * (1.0 + scaled / (white * white)) / (1.0 + scaled)
    ratio = np.divide(ld, lw, out=np.zeros_like(lw), where=lw > 0)
    m = (np.asarray(mask) > 0.5)[..., None]
    return np.where(m, colour * ratio[..., None], colour)
