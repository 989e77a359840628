"""Summary figures of an HDR image in either layout (what `arsim info` prints)."""

from __future__ import annotations

import numpy as np

from arsim.core.conventions import anglemap_disk_mask, anglemap_solid_angles, equirect_solid_angles
from arsim.core.resample import detect_layout


def image_stats(image: np.ndarray) -> dict:
    """Layout, radiance range and means over the texels on the sphere (the disk of an angle map), the
    sphere mean weighted by texel solid angle, and counts of NaN, Inf and negative texels."""
    layout = detect_layout(image)
    h, w = image.shape[:2]
    if layout == "anglemap":
        inside, weights = anglemap_disk_mask(h), anglemap_solid_angles(h)
    else:
        inside, weights = np.ones((h, w), dtype=bool), equirect_solid_angles(h)
    texels = image[inside].astype(np.float64)
    finite = np.isfinite(texels).all(axis=-1)
    good = texels[finite]
    sphere = np.where(np.isfinite(image), image, 0.0).astype(np.float64)
    sphere_mean = (sphere * weights[..., None]).sum(axis=(0, 1)) / weights.sum()
    empty = good.size == 0
    return {
        "width": w,
        "height": h,
        "layout": layout,
        "texels": int(inside.sum()),
        "min": None if empty else float(good.min()),
        "max": None if empty else float(good.max()),
        "mean": None if empty else float(good.mean()),
        "mean_rgb": None if empty else [float(v) for v in good.mean(axis=0)],
        "sphere_mean_rgb": [float(v) for v in sphere_mean],
        "nan": int(np.isnan(image).any(axis=-1).sum()),
        "inf": int(np.isinf(image).any(axis=-1).sum()),
        "negative": int((image < 0).any(axis=-1).sum()),
    }
