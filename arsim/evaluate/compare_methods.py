"""Compare map methods against `accurate`: the thesis's tables 6.1-6.3, its figure 6.4, and SH error
against order (stable and thesis-faithful evaluation)."""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
from arsim.core.files import atomic_path, write_text_atomic
from arsim.core.hdr_io import tonemap_preview
from arsim.evaluate.metrics import map_error
from arsim.lighting.accurate import lobe_average_at
from arsim.lighting.methods import MapParameters, bake, method
from arsim.lighting.sh import sh_maps

DEFAULT_SH_ORDERS = (5, 10, 20, 35, 64, 128)
FULL_REFERENCE_MAX_SIZE = 128


@dataclass
class Comparison:
    """Everything compare-methods measured, ready for tables and plots."""

    size: int
    exponents: list[float]
    reference_texels: int
    reference_seconds: float
    errors: dict[str, list[dict]] = field(default_factory=dict)  # method -> per exponent {mean, max}
    seconds: dict[str, float] = field(default_factory=dict)
    maps: dict[str, np.ndarray] = field(default_factory=dict)  # method -> (E, N, N, 3)
    sh_orders: list[int] = field(default_factory=list)
    sh_error_by_order: dict[str, list[list[float]]] = field(default_factory=dict)  # mode -> [order][exponent] mean %

    def to_json(self) -> dict:
        return {
            "size": self.size,
            "exponents": self.exponents,
            "reference": {"method": "accurate", "texels": self.reference_texels, "seconds": self.reference_seconds},
            "errors_percent": self.errors,
            "seconds": self.seconds,
            "sh_orders": self.sh_orders,
            "sh_mean_error_percent_by_order": self.sh_error_by_order,
        }


def reference_texels(n: int, count: int | None, seed: int = 0) -> np.ndarray:
    """Flat indices of the texels `accurate` is evaluated at: all disk texels up to 128², else `count`
    random ones (the accurate sum costs N^4)."""
    disk = np.flatnonzero(anglemap_disk_mask(n).ravel())
    if count is None:
        count = len(disk) if n <= FULL_REFERENCE_MAX_SIZE else 2000
    if count >= len(disk):
        return disk
    return np.sort(np.random.default_rng(seed).choice(disk, count, replace=False))


def _errors(reference: np.ndarray, maps: np.ndarray, texels: np.ndarray) -> list[dict]:
    out = []
    for k in range(maps.shape[0]):
        e = map_error(reference[:, k], maps[k].reshape(-1, 3)[texels])
        out.append({"mean": e.mean_percent, "max": e.max_percent})
    return out


def check_request(methods: Sequence[str], params: MapParameters, sh_orders: Sequence[int]) -> None:
    """Refuse, before any work, an unknown method, a parameter out of range or an SH order out of range
    (each order of the study as the sh method takes it)."""
    for name in methods:
        method(name)
    params.check()
    for order in sh_orders:
        dataclasses.replace(params, sh_order=int(order)).check()


def compare(env: np.ndarray, exponents: Sequence[float], methods: Sequence[str], params: MapParameters,
            texel_count: int | None = None, sh_orders: Sequence[int] = DEFAULT_SH_ORDERS,
            progress: Callable[[str], None] = lambda stage: None) -> Comparison:
    """Run every method on env, measure each against accurate at the reference texels."""
    check_request(methods, params, sh_orders)
    n = env.shape[0]
    texels = reference_texels(n, texel_count)
    progress(f"accurate reference at {len(texels)} texels")
    start = time.perf_counter()
    reference = lobe_average_at(env, exponents, anglemap_directions(n).reshape(-1, 3)[texels])
    result = Comparison(n, [float(s) for s in exponents], len(texels), time.perf_counter() - start)
    if len(texels) == int(anglemap_disk_mask(n).sum()):  # a full reference shows in the figure too
        full = np.zeros((len(exponents), n * n, 3), dtype=np.float32)
        full[:, texels] = reference.transpose(1, 0, 2)
        result.maps["accurate"] = full.reshape(len(exponents), n, n, 3)
    for name in methods:
        progress(name)
        if name == "accurate" and len(texels) < int(anglemap_disk_mask(n).sum()):
            continue  # accurate maps in full are N^4 work; the subset above is the reference
        baked = bake(env, exponents, name, params)
        result.maps[name] = baked.maps
        result.seconds[name] = baked.seconds_total
        result.errors[name] = _errors(reference, baked.maps, texels)
    if sh_orders:
        result.sh_orders = [int(o) for o in sh_orders]
        for mode, faithful in (("stable", False), ("faithful", True)):
            progress(f"SH error against order ({mode})")
            rows = []
            for order in result.sh_orders:
                values = sh_maps(env, exponents, order, faithful).reshape(len(exponents), -1, 3)[:, texels]
                rows.append([map_error(reference[:, k], values[k]).mean_percent for k in range(len(exponents))])
            result.sh_error_by_order[mode] = rows
    return result


def _fmt_exponent(s: float) -> str:
    return str(int(s)) if float(s).is_integer() else f"{s:g}"


def markdown_tables(c: Comparison) -> str:
    """Tables like the thesis's 6.1-6.3: mean and max error per method and exponent, and times."""
    head = "| method | " + " | ".join(f"s={_fmt_exponent(s)}" for s in c.exponents) + " |"
    rule = "|---|" + "---|" * len(c.exponents)
    lines = [f"# Map methods against accurate ({c.size}² angle map)", "",
             f"Reference: `accurate` at {c.reference_texels} texels ({c.reference_seconds:.1f} s). Error per texel "
             "and channel |a - v| / (a + ε), ε = 1e-4·mean(a), in percent.", "",
             "## Mean error (%)", "", head, rule]
    for name, errs in c.errors.items():
        lines.append(f"| {name} | " + " | ".join(f"{e['mean']:.3f}" for e in errs) + " |")
    lines += ["", "## Max error (%)", "", head, rule]
    for name, errs in c.errors.items():
        lines.append(f"| {name} | " + " | ".join(f"{e['max']:.2f}" for e in errs) + " |")
    lines += ["", f"## Time for all {len(c.exponents)} maps", "", "| method | seconds |", "|---|---|"]
    for name, sec in c.seconds.items():
        lines.append(f"| {name} | {sec:.2f} |")
    if c.sh_orders:
        lines += ["", "## SH mean error (%) against order", ""]
        for mode, rows in c.sh_error_by_order.items():
            lines += [f"### {mode} Y_lm", "", "| order | " + " | ".join(f"s={_fmt_exponent(s)}" for s in c.exponents) + " |",
                      "|---|" + "---|" * len(c.exponents)]
            for order, row in zip(c.sh_orders, rows):
                lines.append(f"| {order} | " + " | ".join(f"{v:.3f}" for v in row) + " |")
            lines.append("")
    return "\n".join(lines) + "\n"


def _save_figure(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")


def figure_grid(c: Comparison, path: Path) -> None:
    """Figure 6.4: rows = methods, columns = exponents, each map tone-mapped on its own."""
    maps_grid(c.maps, c.exponents, path, f"Irradiance (s = 1) and reflection maps by method, {c.size}² angle maps")


def maps_grid(maps: dict[str, np.ndarray], exponents: Sequence[float], path: Path, title: str) -> None:
    """A row per method (its (E, N, N, 3) maps), a column per exponent, each map tone-mapped on its own."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(maps)
    fig, axes = plt.subplots(len(names), len(exponents), figsize=(1.6 * len(exponents), 1.7 * len(names)),
                             squeeze=False)
    for i, name in enumerate(names):
        for j, s in enumerate(exponents):
            ax = axes[i, j]
            ax.imshow(tonemap_preview(maps[name][j]))
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(f"s = {_fmt_exponent(s)}", fontsize=9)
            if j == 0:
                ax.set_ylabel(name, fontsize=9)
    fig.suptitle(title, fontsize=10)
    _save_figure(fig, path)
    plt.close(fig)


def sh_order_plot(c: Comparison, path: Path) -> None:
    """Mean error against SH order per exponent, stable (solid) and thesis-faithful (dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(c.exponents)))
    for k, s in enumerate(c.exponents):
        for mode, style in (("stable", "-"), ("faithful", "--")):
            rows = c.sh_error_by_order.get(mode)
            if rows:
                ax.plot(c.sh_orders, [max(r[k], 1e-6) for r in rows], style, color=colours[k], marker="o", ms=3,
                        label=f"s={_fmt_exponent(s)}" if mode == "stable" else None)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("SH order (bands 0..order-1)")
    ax.set_ylabel("mean error against accurate (%)")
    ax.set_title("SH maps: stable recurrences (solid) and Alg. 2.5/2.6 factorials (dashed)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    _save_figure(fig, path)
    plt.close(fig)


def write_comparison(c: Comparison, out_dir: Path) -> list[Path]:
    """tables.md, tables.json, methods.png and sh_order.png in out_dir; returns the paths."""
    paths = [out_dir / "tables.md", out_dir / "tables.json"]
    write_text_atomic(paths[0], markdown_tables(c))
    write_text_atomic(paths[1], json.dumps(c.to_json(), indent=2) + "\n")
    if c.maps:
        paths.append(out_dir / "methods.png")
        figure_grid(c, paths[-1])
    if c.sh_orders:
        paths.append(out_dir / "sh_order.png")
        sh_order_plot(c, paths[-1])
    return paths
