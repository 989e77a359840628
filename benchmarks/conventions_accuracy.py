"""Accuracy figures of the conventions and the layout conversion (prints figures; not a test).

    python benchmarks/conventions_accuracy.py
"""


import numpy as np

from arsim.core.assets import assets_dir
from arsim.core.conventions import (
    angle_between,
    anglemap_solid_angles,
    anglemap_st_to_direction,
    direction_to_anglemap_st,
    direction_to_equirect_uv,
    equirect_solid_angles,
    equirect_uv_to_direction,
)
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout

ENVMAPS = sorted((assets_dir() / "envmaps").glob("*.exr"))


def sphere_mean(image: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    weights = anglemap_solid_angles(h) if h == w else equirect_solid_angles(h)
    return (image.astype(np.float64) * weights[..., None]).sum(axis=(0, 1)) / weights.sum()


def main() -> None:
    rng = np.random.default_rng(0)
    d = rng.normal(size=(2_000_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    angle = np.geomspace(1e-15, 1e-6, 200_000)
    phi = rng.uniform(0, 2 * np.pi, angle.size)
    near = np.stack([np.sin(angle) * np.cos(phi), np.sin(angle) * np.sin(phi), -np.cos(angle)], axis=-1)
    for name, batch in (("2M random directions", d), ("200k within 1e-6 rad of -z", near)):
        am = angle_between(batch, anglemap_st_to_direction(direction_to_anglemap_st(batch))).max()
        eq = angle_between(batch, equirect_uv_to_direction(direction_to_equirect_uv(batch))).max()
        print(f"round trip, {name:<28} angle map max {am:.2e} rad   equirect max {eq:.2e} rad")
    for n in (256, 512, 1024):
        total = anglemap_solid_angles(n).sum()
        print(f"angle map N={n:<5} solid angles sum to 4pi x {total / (4 * np.pi):.8f}")
    for h in (256, 512):
        print(f"equirect H={h:<5} solid angles sum to 4pi x {equirect_solid_angles(h).sum() / (4 * np.pi):.12f}")
    print(f"\n{'asset':<11} {'eq->am512 change':>17} {'eq->am512->eq change':>21}   (sphere mean radiance, worst channel)")
    for path in ENVMAPS:
        eq = read_hdr(path)
        am = to_layout(eq, "anglemap", 512)
        back = to_layout(am, "equirect", eq.shape[0])
        ref = sphere_mean(eq)
        a = 100 * np.abs(sphere_mean(am) / ref - 1).max()
        b = 100 * np.abs(sphere_mean(back) / ref - 1).max()
        print(f"{path.stem:<11} {a:>16.3f}% {b:>20.3f}%")


if __name__ == "__main__":
    main()
