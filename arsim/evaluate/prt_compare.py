"""`arsim prt compare`: the normal-mapping-prt spec's variants against a per-pixel reference, and the
hemispherical bases' fits of the quadratic SH.

The object is inm_compare's: the normal-mapped torus on the table, seen from 0.2 m and ray-cast in NumPy.
The reference integrates per pixel the light with the normal map's normal over the surface's hemisphere,
with a ray to each of the light's texels for the visibility (torus and table). PRT: the transfer per
texel of the torus's light map (computed once, for every light: it does not depend on it), relit per
probe, looked up at the pixel's texel and evaluated with the normal map's tangent-space normal; "prt" is
the spec's baseline, the shadowed diffuse transfer vector at the surface's own normal (no normal map).

sh_projection: for each of the nine real orthonormal SH of bands 0-2 (z the tangent frame's normal), the
squared error of its least-squares fit in each hemispherical basis, integrated over the upper hemisphere.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from arsim.core.resample import to_layout
from arsim.evaluate.inm_compare import (
    MAJOR,
    MINOR,
    _blocked,
    reference_visibility,
    sample_periodic,
    srgb8,
    torus_reference,
    torus_view,
)
from arsim.lighting import prt
from arsim.lighting.bases.functions import get_basis, sh9
from arsim.lighting.bases.lightmap import probe_samples
from arsim.lighting.bases.quadrature import hemisphere_quadrature
from arsim.render.content import torus_texels

SH9_NAMES = ["Y00", "Y1-1", "Y10", "Y11", "Y2-2", "Y2-1", "Y20", "Y21", "Y22"]
# The hemispherical bases the nine SH are fitted in (the JSON's keys): a bases.functions name and count,
# or the separable basis.
PROJECTION_BASES = {"hl2": ("hl2", 3), "sal4": ("hsh", 4), "sal9": ("hsh", 9), "h4": ("h", 4), "h6": ("h", 6),
                    "sep4": ("sep", 4)}


def sh_projection() -> dict:
    """{"functions": the nine names, "mse": {basis: nine squared errors}}: per SH of bands 0-2, int over the
    upper hemisphere of (Y - its least-squares fit in the basis)^2 (a Gauss rule exact for the polynomial
    bases; the separable basis's table read as the renderer reads it)."""
    d, w = hemisphere_quadrature()
    y = sh9(d)  # (K, 9)
    out = {}
    for key, (name, count) in PROJECTION_BASES.items():
        b = prt.separable(False, count).evaluate(d) if name == "sep" else get_basis(name).evaluate(d, count)
        weighted = b * w[:, None]
        fit = b @ np.linalg.solve(weighted.T @ b, weighted.T @ y)  # (K, 9) the fits at the rule's points
        out[key] = [float(v) for v in ((y - fit) ** 2 * w[:, None]).sum(axis=0)]
    return {"functions": SH9_NAMES, "mse": out}


def sh_projection_markdown(table: dict) -> str:
    lines = ["# The quadratic SH fitted in hemispherical bases", "",
             "Squared error of each real orthonormal SH function's least-squares fit over the upper hemisphere "
             "(z the normal), out of 0.5, each function's own integral of Y^2 there (every Y_lm is even or odd in z). "
             "sep4: the separable basis of 4 terms (C applied after), read from its 64 x 64 table.", "",
             "| basis | " + " | ".join(table["functions"]) + " |", "|---|" + "---:|" * 9]
    for key, errors in table["mse"].items():
        lines.append(f"| {key} | " + " | ".join(f"{e:.2e}" for e in errors) + " |")
    return "\n".join(lines) + "\n"


@dataclass
class PrtComparison:
    """Per probe: the reference and each variant's image (H, W, 3) of E / pi, and the hit pixels."""

    reference: dict[str, np.ndarray]
    images: dict[str, dict[str, np.ndarray]]  # probe -> variant -> image
    hit: np.ndarray
    timings: dict[str, float]  # seconds: the transfer, the reference's visibility, relighting per probe


def compare_prt(probes: dict[str, np.ndarray], variants=prt.VARIANTS, order: int = prt.DEFAULT_ORDER,
                samples: int = 1024, width: int = 160, height: int = 120, lightmap_size: tuple[int, int] = (32, 64),
                light_size: int = 32, progress=lambda fraction, label: None) -> PrtComparison:
    """The torus under each angle-map probe: the per-pixel reference, the baseline "prt" and every variant."""
    for v in variants:
        prt.get_variant(v)
    prt.check_order(order)
    timings = {}
    start = time.perf_counter()
    points, normals, tangents = (a.reshape(-1, 3) for a in torus_texels(MAJOR, MINOR, lightmap_size))
    texels = len(points)
    transfer = prt.compute_transfer(points, normals, tangents, order, _blocked, samples,
                                    progress=lambda n, done=[0]: (done.__setitem__(0, done[0] + n),
                                                                  progress(0.5 * done[0] / texels, "transfer")))
    timings["transfer_s"] = time.perf_counter() - start
    view = torus_view(width, height)
    start = time.perf_counter()
    directions, _ = probe_samples(to_layout(next(iter(probes.values())), "anglemap", light_size))
    visibility = reference_visibility(view, directions)  # (the same rays for every probe)
    timings["reference_visibility_s"] = time.perf_counter() - start
    progress(0.8, "reference")
    uv = view.uv[view.hit]
    reference, images = {}, {}
    relight_s = []
    for name, probe in probes.items():
        pixels = torus_reference(probe, width, height, light_size, visibility=visibility)
        reference[name] = _image(view.hit, pixels.reference / np.pi)
        light = prt.light_sh(to_layout(probe, "anglemap", 128), order)
        per_probe = {"prt": _image(view.hit, sample_periodic((transfer.shadowed @ light).reshape(*lightmap_size, 3), uv) / np.pi)}
        for v in variants:
            variant = prt.get_variant(v)
            matrices = prt.variant_transfer(transfer, variant)
            start = time.perf_counter()
            coefficients = prt.relight(matrices, light)
            relight_s.append(time.perf_counter() - start)
            c = sample_periodic(coefficients.reshape(*lightmap_size, -1), uv).reshape(-1, variant.count, 3)
            per_probe[v] = _image(view.hit, prt.prt_diffuse(c, variant, pixels.n_tangent))
        images[name] = per_probe
    timings["relight_s_median"] = float(np.median(relight_s))
    progress(1.0, "done")
    return PrtComparison(reference, images, view.hit, timings)


def _image(hit: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.zeros(hit.shape + (3,))
    out[hit] = values
    return out


def exposure_of(reference: np.ndarray, hit: np.ndarray) -> float:
    return 0.9 / float(np.percentile(reference[hit].max(axis=-1), 99))


def prt_scores(c: PrtComparison) -> dict[str, dict[str, dict[str, float]]]:
    """probe -> lighting -> FLIP (LDR, on the reference's exposure) and the relative mean squared error."""
    from arsim.evaluate.flip import masked_flip

    out = {}
    for probe, reference in c.reference.items():
        exposure = exposure_of(reference, c.hit)
        ref8 = srgb8(reference, exposure)
        power = float((reference[c.hit] ** 2).mean())
        out[probe] = {name: {"flip": masked_flip(ref8, srgb8(image, exposure), c.hit),
                             "mse": float(((image[c.hit] - reference[c.hit]) ** 2).mean()) / power}
                      for name, image in c.images[probe].items()}
    return out


def comparison_image(c: PrtComparison) -> np.ndarray:
    """A row per probe: reference | prt | each variant, on the reference's exposure, labelled (the spec's
    figure 3, side by side)."""
    import cv2

    rows = []
    for probe, reference in c.reference.items():
        exposure = exposure_of(reference, c.hit)
        tiles = []
        for name, image in {"reference": reference, **c.images[probe]}.items():
            tile = np.ascontiguousarray(srgb8(image, exposure))
            label = f"{probe}: {name}" if name == "reference" else name
            cv2.putText(tile, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
            tiles.append(tile)
        rows.append(np.concatenate(tiles, axis=1))
    return np.concatenate(rows, axis=0)


def scores_markdown(scores: dict, timings: dict, order: int, samples: int) -> str:
    names = list(next(iter(scores.values())))
    lines = ["# PRT with normal maps against the per-pixel reference", "",
             f"The normal-mapped torus on the table, the transfer per texel of its 32 x 64 light map (order {order}, "
             f"{samples} directions per texel, shadows by the torus and the table). Per probe and lighting: FLIP (LDR, "
             "one exposure) / the mean squared error relative to the reference's mean square.", "",
             "| probe | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for probe, row in scores.items():
        lines.append(f"| {probe} | " + " | ".join(f"{row[n]['flip']:.3f} / {row[n]['mse']:.4f}" for n in names) + " |")
    lines += ["", f"Transfer: {timings['transfer_s']:.1f} s (once, for every probe); relighting the light map: "
              f"{1000 * timings['relight_s_median']:.2f} ms (median over variants and probes).", ""]
    return "\n".join(lines)


DEFAULT_PROBES = ("interior", "sunrise", "city")  # the bundled environments the comparison uses by default


def prt_study(out_dir, probes: dict[str, np.ndarray], variants=prt.VARIANTS, order: int = prt.DEFAULT_ORDER,
              samples: int = 1024, progress=lambda fraction, label: None) -> tuple[list, dict]:
    """Everything `arsim prt compare` writes into out_dir: prt_compare.md/.json (scores per probe and
    lighting, timings), variants.png (the images side by side), sh_projection.json/.md. Returns the paths
    and the scores."""
    from pathlib import Path

    from arsim.core.files import json_text, write_bytes_atomic, write_text_atomic
    from arsim.core.png import png_bytes

    out_dir = Path(out_dir)
    comparison = compare_prt(probes, variants, order, samples, progress=progress)
    scores = prt_scores(comparison)
    paths = [out_dir / n for n in ("prt_compare.json", "prt_compare.md", "variants.png", "sh_projection.json",
                                   "sh_projection.md")]
    write_text_atomic(paths[0], json_text({"order": order, "samples": samples, "variants": list(variants),
                                           "scores": scores, "timings": comparison.timings}))
    write_text_atomic(paths[1], scores_markdown(scores, comparison.timings, order, samples))
    write_bytes_atomic(paths[2], png_bytes(comparison_image(comparison)))
    table = sh_projection()
    write_text_atomic(paths[3], json_text(table))
    write_text_atomic(paths[4], sh_projection_markdown(table))
    return paths, scores
