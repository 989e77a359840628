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
    """The scene's average luminance over the masked pixels: their mean, what the top of the mip chain
    gives (thesis 5.3.4), or Reinhard's log-average exp(mean(log(delta + L_w)))."""
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
