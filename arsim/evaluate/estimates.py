"""Light estimates scored against the truth, per frame and over the sweep (README: Light estimation):
per estimator, the SH coefficients' relative error, the main light's direction error and luminance ratio,
the ambient intensity's ratio; at the end of the sweep, their convergence (the first frame from which the
SH error stays within 5 % of the truth's norm of its final value) and their stability (the mean change of
the SH from frame to frame, over the truth's norm: the true light does not change)."""

from __future__ import annotations

import numpy as np

from arsim.evaluate.light_metrics import direction_error_deg, intensity_ratio, sh_relative_error

ESTIMATORS = ("capture", "single", "file")  # (and the truth's own estimate, where the AR objects are lit by it)


def frame_scores(line: dict, name: str) -> dict | None:
    """One estimator's scores in one line of estimates.jsonl (None where it has no estimate there)."""
    if name not in line:
        return None
    e, t = line[name], line["truth"]
    return {"sh_error": sh_relative_error(e["sh_radiance"], t["sh_radiance"]),
            "main_light_error_deg": direction_error_deg(e["main_light"]["direction_world"], t["main_light"]["direction_world"]),
            "main_light_intensity_ratio": intensity_ratio(e["main_light"]["intensity_rgb"], t["main_light"]["intensity_rgb"]),
            "ambient_ratio": e["ambient_intensity"] / max(t["ambient_intensity"], 1e-300)}


def scores(lines: list[dict]) -> dict:
    """Per estimator present: its final scores (at the last frame it has), the medians over its frames,
    its convergence frame and its stability."""
    out = {}
    truth_norm = np.linalg.norm(lines[0]["truth"]["sh_radiance"])
    for name in ESTIMATORS:
        frames = [(line["frame"], frame_scores(line, name), line[name]) for line in lines if name in line]
        if not frames:
            continue
        errors = np.array([s["sh_error"] for _, s, _ in frames])
        final = errors[-1]
        outside = np.flatnonzero(np.abs(errors - final) > 0.05)
        converged = frames[outside[-1] + 1][0] if len(outside) and outside[-1] + 1 < len(frames) else (
            frames[0][0] if not len(outside) else None)
        sh = np.array([e["sh_radiance"] for _, _, e in frames])
        steps = np.linalg.norm(np.diff(sh, axis=0), axis=1) / truth_norm if len(sh) > 1 else np.zeros(1)
        keys = frames[0][1].keys()
        out[name] = {"frames": len(frames), "final": frames[-1][1],
                     "median": {k: float(np.median([s[k] for _, s, _ in frames])) for k in keys},
                     "converged_at_frame": converged, "stability": float(np.mean(steps))}
    return out


def plot_scores(lines: list[dict], path) -> None:
    """The SH error and the main light's direction error over the frames, a line per estimator."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from arsim.core.files import atomic_path

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 5.5), dpi=110, sharex=True)
    for name in ESTIMATORS:
        frames = [(line["frame"], frame_scores(line, name)) for line in lines if name in line]
        if frames:
            k = [f for f, _ in frames]
            top.plot(k, [100 * s["sh_error"] for _, s in frames], label=name)
            bottom.plot(k, [s["main_light_error_deg"] for _, s in frames], label=name)
    top.set_ylabel("SH error\n(% of the truth's SH norm)")
    bottom.set_ylabel("main light's direction\nerror (degrees)")
    bottom.set_xlabel("frame of the sweep (index)")
    top.set_title("Light estimates against the truth")
    top.legend()
    top.grid(alpha=0.3)
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def sphere_figures(figures: dict, truth: np.ndarray | None, estimates: dict, given: dict | None, path) -> dict:
    """The scores with each estimator's three spheres at the end of the sweep against the truth's
    (spheres.py; the truth's own estimate among them: what the shapes allow): from its last estimate (LightEstimate:
    SH, main light and cubemap), and the file's diffuse sphere from its SH and main light (a file gives no cubemap);
    spheres.png shows them, a row each, on the truth's exposure. Without the truth (None): the estimates' spheres
    alone, on the first one's exposure, and no scores."""
    from arsim.evaluate.spheres import estimate_spheres, sphere_scores, truth_spheres

    reference = truth_spheres(truth) if truth is not None else None
    rows = {"truth": reference} if reference is not None else {}
    for name, e in estimates.items():
        row = "truth's estimate" if name == "truth" else name  # (the row "truth" is the true light itself)
        rows[row] = estimate_spheres(e.sh_radiance, e.main_light_direction, e.main_light_intensity, e.cubemap)
        if reference is not None:
            figures.setdefault(name, {})["spheres"] = sphere_scores(rows[row], reference)  # (the truth's: spheres only)
    if given is not None and (reference is None or "file" in figures):
        light = given["main_light"]
        mine = estimate_spheres(np.asarray(given["sh_radiance"]), light["direction_world"], light["intensity_rgb"], None)
        if reference is not None:
            figures["file"]["spheres"] = {"diffuse": sphere_scores(mine, reference)["diffuse"]}
        rows["file (no cubemap)"] = mine
    _sphere_image(rows, path)
    return figures


def _srgb_encode(v: np.ndarray) -> np.ndarray:
    v = np.clip(v, 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def _srgb_decode(v: np.ndarray) -> np.ndarray:
    v = np.clip(v, 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def sphere_figure(rows: dict):
    """A row per light (the truth's first, where known), a column per sphere; each column on one exposure
    (its first row's 99th percentile to 0.9), with a colour bar of the radiance each shade stands for."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import FuncNorm

    from arsim.evaluate.inm_compare import srgb8
    from arsim.evaluate.spheres import ALBEDO, SILVER_EXPONENT

    reference = next(iter(rows.values()))  # (the truth's, where known)
    lit = [reference[k][reference[k].max(axis=-1) > 0].max(axis=-1) for k in range(3)]
    exposures = [0.9 / max(float(np.percentile(v, 99)) if v.size else 0.0, 1e-12) for v in lit]
    columns = (f"diffuse (albedo {ALBEDO:g})", f"matte silver (Phong s = {SILVER_EXPONENT:g})", "mirror")
    fig, axes = plt.subplots(len(rows), 3, figsize=(7.2, 1.75 * len(rows) + 1.3), squeeze=False, layout="constrained")
    for i, (name, spheres) in enumerate(rows.items()):
        for k in range(3):
            ax = axes[i, k]
            ax.imshow(srgb8(spheres[k], exposures[k]))
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(columns[k], fontsize=9)
            if k == 0:
                ax.set_ylabel(name, fontsize=9)
    for k in range(3):  # the shade of each radiance on the column's exposure (sRGB)
        e = exposures[k]
        norm = FuncNorm((lambda x, e=e: _srgb_encode(np.asarray(x) * e), lambda y, e=e: _srgb_decode(np.asarray(y)) / e),
                        vmin=0.0, vmax=1.0 / e)
        bar = fig.colorbar(ScalarMappable(norm, cmap="gray"), ax=axes[:, k].tolist(), orientation="horizontal",
                           fraction=0.04, pad=0.02, extend="max", label="radiance (the light's units)")
        # ticks evenly spaced along the bar (sRGB crowds the linear ones at its bright end), two digits
        bar.set_ticks([0.0] + [float(f"{_srgb_decode(np.array(y)) / e:.2g}") for y in (0.35, 0.7, 1.0)])
    fig.suptitle("Three spheres seen from +z (right +x, up +y), lit by each light; a column on one exposure (sRGB)",
                 fontsize=9)
    return fig


def _sphere_image(rows: dict, path) -> None:
    import matplotlib.pyplot as plt

    from arsim.core.files import atomic_path

    fig = sphere_figure(rows)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)


def estimate_summary(figures: dict, ar_scores: dict) -> dict:
    """metrics.json's `estimates`: per estimator its scores at the sweep's end (SH error, main light, ambient,
    diffuse and mirror spheres), its convergence and stability, and the FLIP of the AR objects lit by it
    against the truth frame (the mean over the frames shown, and per frame)."""
    out = {}
    for name in ("truth", *ESTIMATORS):
        f = figures.get(name)
        scored = ar_scores.get(name, {})
        if f is None and not scored:
            continue
        row = {}
        if f is not None:
            spheres = f.get("spheres", {})
            row = dict(f.get("final", {}), **{k: f[k] for k in ("converged_at_frame", "stability") if k in f},
                       diffuse_sphere_rmse=spheres.get("diffuse", {}).get("rmse"),
                       mirror_sphere_hdr_flip=spheres.get("mirror", {}).get("hdr_flip"))
        if scored:
            row["ar_flip_mean"] = float(np.mean(list(scored.values())))
            row["ar_flip_per_frame"] = {str(k): v for k, v in sorted(scored.items())}
        out[name] = row
    return out


CROP_MARGIN = 24  # pixels around the objects in the frames compared
CROP_HEIGHT = 180  # the crops' height in estimates/frames/*.png


def write_estimate_frames(frames: dict, folder) -> list:
    """Per frame shown (render.session's estimate_frames): a PNG of the objects' region in the truth frame
    and lit by each estimate, the FLIP error of each below it (magma, 0 to 1) with its mean over the objects
    (without a truth frame: the objects' mask and the frames lit by each estimate, in one row);
    returns the paths written. The error maps are the frames' own ("errors", where the session made them), else
    flip_map's."""
    import cv2

    from arsim.core.files import write_bytes_atomic
    from arsim.core.png import png_bytes
    from arsim.evaluate.diff import magma
    from arsim.evaluate.flip import flip_map

    written = []
    for k, shown in sorted(frames.items()):
        folder.mkdir(parents=True, exist_ok=True)
        mask, truth = shown["mask"], shown["truth_frame"]
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        box = (slice(max(rows[0] - CROP_MARGIN, 0), rows[-1] + CROP_MARGIN + 1),
               slice(max(cols[0] - CROP_MARGIN, 0), cols[-1] + CROP_MARGIN + 1))
        scale = CROP_HEIGHT / (box[0].stop - box[0].start)
        size = (max(int(round((box[1].stop - box[1].start) * scale)), 1), CROP_HEIGHT)

        def tile(image, label):
            t = np.ascontiguousarray(np.pad(cv2.resize(image[box], size, interpolation=cv2.INTER_NEAREST), ((16, 0), (0, 4), (0, 0))))
            cv2.putText(t, label, (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
            return t

        top = [tile(truth, "truth frame")] if truth is not None else []
        bottom = [tile(np.repeat(mask[..., None], 3, axis=-1).astype(np.uint8) * 255, "objects' mask")]
        for name, image in shown["lit"].items():
            top.append(tile(image, f"{name}'s estimate"))
            if truth is not None:
                error = shown.get("errors", {}).get(name)
                error = flip_map(truth, image, mask) if error is None else error
                bottom.append(tile(magma(error), f"FLIP {float(error[mask].mean()):.4f}"))
        if truth is None:  # (no truth frame: the estimates' frames beside the objects' mask, nothing scored)
            top, bottom = bottom + top, []
        rows = [np.concatenate(r, axis=1) for r in (top, bottom) if r]
        path = folder / f"{k:06d}.png"
        write_bytes_atomic(path, png_bytes(np.concatenate(rows, axis=0)))
        written.append(path)
    return written
