"""Plots of a recording: where the camera looked (coverage), exposure and ISO, the IMU signals, and the
fused orientation's error against the truth. Drawn from the files, so they show what was written."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from arsim.core.files import atomic_path
from arsim.sensors.frames import frame_camera_orientations, frame_positions, recording_camera
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


def plot_exposure(rec: Recording, path: Path) -> Path:
    plt = _pyplot()
    t = np.array([f["t_ns"] for f in rec.frames]) / 1e9
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, [f["exposure_ns"] / 1e6 for f in rec.frames], color="tab:blue")
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("exposure (ms)", color="tab:blue")
    other = ax.twinx()
    other.plot(t, [f["iso"] for f in rec.frames], color="tab:orange")
    other.set_ylabel("ISO", color="tab:orange")
    ax.set_title("Auto-exposure: exposure time and ISO per frame")
    return _save(fig, path)


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
    top.scatter(p[:, 0], p[:, 2], c=np.where(seen, "tab:green", "tab:red"), s=4)
    top.set_aspect("equal")
    top.set_xlabel("world x (m)")
    top.set_ylabel("world z (m)")
    top.set_title("path from above (green: tag in view)")
    t = np.array([f["t_ns"] for f in rec.frames]) / 1e9
    timeline.plot(t, np.linalg.norm(p, axis=1), color="tab:blue", label="distance to the tag (m)")
    timeline.fill_between(t, 0, 1, where=~seen, transform=timeline.get_xaxis_transform(), color="tab:red",
                          alpha=0.2, label="tag out of view")
    timeline.set_xlabel("time (s)")
    timeline.set_ylabel("distance (m)")
    timeline.legend(loc="upper right", fontsize=8)
    timeline.set_title(f"AR path: the tag in view in {100 * seen.mean():.1f} % of the frames")
    return {"file": _save(fig, path), "tag_in_view": float(seen.mean())}
