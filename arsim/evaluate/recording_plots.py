"""Plots of a recording: where the camera looked (coverage), exposure and ISO, the IMU signals, and the
fused orientation's error against the truth. Drawn from the files, so they show what was written."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from arsim.core.files import atomic_path
from arsim.sensors.frames import frame_camera_orientations, frame_positions, recording_camera, recording_scenario
from arsim.sensors.coverage import fibonacci_directions, seen_by_views
from arsim.sensors.fusion import tilt_error_deg, yaw_error_deg
from arsim.sensors.recording import Recording


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, bbox_inches="tight")
    _pyplot().close(fig)
    return path


def _lon_lat(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Longitude (as the equirect's phi, degrees, 180 = +z) and latitude (degrees) of directions."""
    lon = np.degrees(np.mod(np.arctan2(d[:, 0], -d[:, 2]), 2 * np.pi))
    return lon, np.degrees(np.arcsin(np.clip(d[:, 1], -1, 1)))


def plot_coverage(rec: Recording, path: Path, samples: int = 20000) -> tuple[Path, float]:
    camera = recording_camera(rec)
    rotations = frame_camera_orientations(rec)
    directions = fibonacci_directions(samples)
    seen = seen_by_views(rotations, camera, directions)
    coverage = float(seen.mean())
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.5))
    lon, lat = _lon_lat(directions[~seen])
    ax.scatter(lon, lat, s=2, color="crimson", label="never seen")
    forward = rotations.apply([0.0, 0.0, 1.0])
    lon, lat = _lon_lat(forward)
    t = np.array([f["t_ns"] for f in rec.frames]) / 1e9
    path_plot = ax.scatter(lon, lat, c=t, s=4, cmap="viridis", label="camera axis")
    fig.colorbar(path_plot, ax=ax, label="time (s)")
    ax.set_xlim(0, 360)
    ax.set_ylim(-90, 90)
    ax.set_xlabel("longitude (degrees, 180 = +z)")
    ax.set_ylabel("latitude (degrees)")
    ax.set_title(f"Capture sweep: the camera's path; {100 * coverage:.2f} % of the sphere seen")
    ax.legend(loc="lower left", fontsize=8)
    return _save(fig, path), coverage


def bracket_offsets(rec: Recording) -> np.ndarray:
    """Per frame: the exposure offset (EV) it was taken at, bracket_ev[k % len] of the recording's scenario
    (0: metered; every frame of a recording without a scenario)."""
    bracket = recording_scenario(rec).capture.bracket_ev
    return np.array([bracket[k % len(bracket)] for k in range(len(rec.frames))], dtype=np.float64)


def _ev_label(ev: float) -> str:
    return "metered (0 EV)" if ev == 0 else f"bracket {ev:+g} EV"


def exposure_figure(rec: Recording):
    """The exposure per frame as one series per bracket offset (the offsets alternate frame by frame, so
    one line through all frames would fill a band): the exposure the frame got (time x ISO / base ISO), its
    exposure time against the sensor's limits, and its ISO."""
    plt = _pyplot()
    camera = recording_scenario(rec).device.camera
    t = np.array([f["t_ns"] for f in rec.frames]) / 1e9
    exposure_ms = np.array([f["exposure_ns"] for f in rec.frames]) / 1e6
    iso = np.array([f["iso"] for f in rec.frames], dtype=np.float64)
    offsets = bracket_offsets(rec)
    levels = sorted(set(offsets.tolist()), key=lambda ev: (ev != 0, -ev))  # metered first, then brightest first
    colours = dict(zip(levels, ["black", "tab:orange", "tab:blue", "tab:green", "tab:purple", "tab:red", "tab:brown"]))
    fig, axes = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True)
    every = len(levels)
    for ev in levels:
        k = offsets == ev
        style = dict(color=colours.get(ev, "tab:gray"), lw=1.4 if ev == 0 else 0.8, marker=None if ev == 0 else ".",
                     ms=3, label=_ev_label(ev) + (f": 1 frame in {every}" if every > 1 else ""))
        axes[0].plot(t[k], exposure_ms[k] * iso[k] / camera.base_iso, **style)
        axes[1].plot(t[k], exposure_ms[k], **style)
        axes[2].plot(t[k], iso[k], **style)
    for limit, what in ((camera.exposure_max_s, "longest"), (camera.exposure_min_s, "shortest")):
        axes[1].axhline(1e3 * limit, color="tab:gray", ls="--", lw=0.8)
        axes[1].annotate(f"sensor's {what} ({1e3 * limit:.3g} ms)", (1.0, 1e3 * limit), xycoords=("axes fraction", "data"),
                         xytext=(-4, 3 if what == "shortest" else -10), textcoords="offset points", ha="right",
                         fontsize=7, color="tab:gray")
    axes[0].set_ylabel(f"exposure at ISO {camera.base_iso:g}\n(time x ISO / {camera.base_iso:g}, ms)")
    axes[1].set_ylabel("exposure time (ms)")
    axes[2].set_ylabel("ISO")
    for ax in axes[:2]:
        ax.set_yscale("log")
    for ax in axes:
        ax.grid(True, which="major", alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=len(levels), fontsize=8, frameon=False)
    axes[0].set_title("Auto-exposure per frame: the metered exposure and the bracket around it", pad=22)
    fig.tight_layout()
    return fig


def plot_exposure(rec: Recording, path: Path) -> Path:
    return _save(exposure_figure(rec), path)


def plot_imu(rec: Recording, path: Path) -> Path:
    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    units = {"gyroscope": "rad/s", "accelerometer": "m/s²", "magnetometer": "µT"}
    for ax, (name, stream) in zip(axes, rec.imu.items()):
        t = stream.t_ns / 1e9
        for k, axis in enumerate("xyz"):
            ax.plot(t, stream.values[:, k], lw=0.6, label=axis)
        ax.set_ylabel(f"{name}\n({units[name]})")
        ax.legend(loc="upper right", fontsize=7, ncol=3)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle("IMU streams in device axes")
    return _save(fig, path)


def plot_orientation_error(rec: Recording, path: Path) -> tuple[Path, float]:
    plt = _pyplot()
    t_ns, fused = rec.orientation
    _, _, truth = rec.groundtruth
    yaw, tilt = yaw_error_deg(fused, truth), tilt_error_deg(fused, truth)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t_ns / 1e9, yaw, label="yaw (heading)")
    ax.plot(t_ns / 1e9, tilt, label="tilt (pitch and roll)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("error (degrees)")
    ax.set_title(f"Fused orientation ({rec.meta['fusion']}) against the truth: yaw {yaw[-1]:+.2f} degrees at the end")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, path), float(yaw[-1])


def plot_recording(rec: Recording, out_dir: Path) -> dict:
    """All four plots into out_dir; returns their paths and the figures they show."""
    out_dir.mkdir(parents=True, exist_ok=True)
    coverage_path, coverage = plot_coverage(rec, out_dir / "coverage.png")
    error_path, final_yaw = plot_orientation_error(rec, out_dir / "orientation_error.png")
    return {
        "files": [coverage_path, plot_exposure(rec, out_dir / "exposure.png"), plot_imu(rec, out_dir / "imu.png"), error_path],
        "coverage": coverage,
        "final_yaw_error_deg": final_yaw,
    }


def tag_in_view(rec: Recording) -> np.ndarray:
    """Per frame of an AR recording: whether all four corners of the tag project inside the image
    (true pose; the tag faces up, so it is never seen from behind on this path)."""
    camera = recording_camera(rec)
    corners = np.array(rec.meta["table"]["tag_corners_world"])
    seen = np.zeros(len(rec.frames), dtype=bool)
    for k, (view, position) in enumerate(zip(frame_camera_orientations(rec), frame_positions(rec))):
        local = view.inv().apply(corners - position)
        if np.all(local[:, 2] > 1e-6):
            px = camera.project(local)
            seen[k] = bool(np.all((px >= -0.5) & (px <= np.array([camera.width, camera.height]) - 0.5)))
    return seen


def plot_ar_path(rec: Recording, path: Path) -> dict:
    """The AR path seen from above around the table and tag, and the tag's visibility and distance
    over time."""
    plt = _pyplot()
    seen = tag_in_view(rec)
    table = rec.meta["table"]
    fig, (top, timeline) = plt.subplots(1, 2, figsize=(11, 4.5), gridspec_kw={"width_ratios": [1, 1.6]})
    w, d = table["size_m"]
    top.add_patch(plt.Rectangle((-w / 2, -d / 2), w, d, color="peru", alpha=0.5, label="table"))
    h = table["tag_size_m"] / 2
    top.add_patch(plt.Rectangle((-h, -h), 2 * h, 2 * h, color="black", label="tag"))
    p = frame_positions(rec)
    top.scatter(p[seen, 0], p[seen, 2], color="tab:green", s=4, label="camera, tag in view")
    top.scatter(p[~seen, 0], p[~seen, 2], color="tab:red", s=4, label="camera, tag out of view")
    top.set_aspect("equal")
    top.legend(loc="upper left", bbox_to_anchor=(0.0, -0.18), fontsize=7, ncol=2, frameon=False)
    top.set_xlabel("world x (m)")
    top.set_ylabel("world z (m)")
    top.set_title("path from above")
    t = np.array([f["t_ns"] for f in rec.frames]) / 1e9
    timeline.plot(t, np.linalg.norm(p, axis=1), color="tab:blue", label="distance to the tag (m)")
    timeline.fill_between(t, 0, 1, where=~seen, transform=timeline.get_xaxis_transform(), color="tab:red",
                          alpha=0.2, label="tag out of view")
    timeline.set_xlabel("time (s)")
    timeline.set_ylabel("distance (m)")
    timeline.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), fontsize=7, ncol=2, frameon=False)
    timeline.set_title(f"AR path: the tag in view in {100 * seen.mean():.1f} % of the frames")
    return {"file": _save(fig, path), "tag_in_view": float(seen.mean())}
