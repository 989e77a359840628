"""Compare map methods against `accurate`: the thesis's tables 6.1-6.3, its figure 6.4, and SH error
against order (stable and thesis-faithful evaluation)."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
from arsim.core.files import atomic_path, write_text_atomic
from arsim.core.hdr_io import tonemap_preview
from arsim.evaluate.metrics import map_error, relative_error
from arsim.lighting.accurate import lobe_average_at
from arsim.lighting.mapset import MapSet
from arsim.lighting.methods import MapParameters, bake, method, sh_orders_used
from arsim.lighting.sh import sh_maps

DEFAULT_SH_ORDERS = (5, 10, 20, 35, 64, 128)
FULL_REFERENCE_MAX_SIZE = 128
# What the SH error-against-order study runs: sh at each order with plain truncation, whatever --sh-window says.
SH_STUDY = "sh, plain truncation (window none), stable and factorial (Alg. 2.5/2.6) Y_lm"


def method_label(name: str, params: MapParameters, exponents: Sequence[float]) -> str:
    """A method's name with what its error depends on: the SH order (per exponent where it varies), and sh's
    window and evaluation; the same in the printed table, the files, the figures and the run's report."""
    orders = sh_orders_used(name, params, exponents)
    if orders is None:
        return name
    if name == "sh":
        extra = f", window {params.sh_window}"
        extra += ", factorial Y_lm" if params.sh_faithful else ""
        return f"sh (order {params.sh_order}{extra})"
    low, high = min(orders), max(orders)
    return f"{name} (SH order {low})" if low == high else f"{name} (SH order {low}-{high} by exponent)"


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
    params: MapParameters = field(default_factory=MapParameters)  # what the methods were run with

    def sh_orders_used(self, name: str) -> list[int] | None:
        """The SH order of each exponent's map for an SH-based method (sh, fast, sht), else None."""
        return sh_orders_used(name, self.params, self.exponents)

    def label(self, name: str) -> str:
        """method_label of a method as this comparison ran it."""
        return method_label(name, self.params, self.exponents)

    def method_parameters(self, name: str) -> dict:
        """tables.json's and tables.csv's record of a method: its label, and for SH-based ones the order of
        each exponent's map and the window (sh's; fast and sht truncate plainly)."""
        orders = self.sh_orders_used(name)
        out: dict = {"label": self.label(name)}
        if orders is not None:
            out |= {"sh_order_per_exponent": orders, "sh_window": self.params.sh_window if name == "sh" else "none"}
            if name == "sh":
                out["sh_faithful"] = self.params.sh_faithful
        return out

    def to_json(self) -> dict:
        return {
            "size": self.size,
            "exponents": self.exponents,
            "reference": {"method": "accurate", "texels": self.reference_texels, "seconds": self.reference_seconds},
            "methods": {name: self.method_parameters(name) for name in self.errors},
            "errors_percent": self.errors,
            "seconds": self.seconds,
            "sh_orders": self.sh_orders,
            "sh_order_study": SH_STUDY,
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
    result = Comparison(n, [float(s) for s in exponents], len(texels), time.perf_counter() - start, params=params)
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
    """Tables like the thesis's 6.1-6.3: mean and max error per method and exponent, and times; each SH-based
    method's row names its SH order (and sh's window), and a table gives the order of every map."""
    head = "| method | " + " | ".join(f"s={_fmt_exponent(s)}" for s in c.exponents) + " |"
    rule = "|---|" + "---|" * len(c.exponents)
    lines = [f"# Map methods against accurate ({c.size}² angle map)", "",
             f"Reference: `accurate` at {c.reference_texels} texels ({c.reference_seconds:.1f} s). Error per texel "
             "and channel |a - v| / (a + ε), ε = 1e-4·mean(a), in percent. SH order L: bands 0..L-1.", "",
             "## Mean error (%)", "", head, rule]
    for name, errs in c.errors.items():
        lines.append(f"| {c.label(name)} | " + " | ".join(f"{e['mean']:.3f}" for e in errs) + " |")
    lines += ["", "## Max error (%)", "", head, rule]
    for name, errs in c.errors.items():
        lines.append(f"| {c.label(name)} | " + " | ".join(f"{e['max']:.2f}" for e in errs) + " |")
    lines += ["", f"## Time for all {len(c.exponents)} maps", "", "| method | seconds |", "|---|---|"]
    for name, sec in c.seconds.items():
        lines.append(f"| {c.label(name)} | {sec:.2f} |")
    sh_based = [name for name in c.errors if c.sh_orders_used(name) is not None]
    if sh_based:
        lines += ["", "## SH order of each map (bands 0..order-1)", "", head, rule]
        for name in sh_based:
            lines.append(f"| {c.label(name)} | " + " | ".join(str(o) for o in c.sh_orders_used(name)) + " |")
    if c.sh_orders:
        lines += ["", "## SH mean error (%) against order", "", f"The study: {SH_STUDY}.", ""]
        for mode, rows in c.sh_error_by_order.items():
            lines += [f"### {mode} Y_lm", "", "| SH order | " + " | ".join(f"s={_fmt_exponent(s)}" for s in c.exponents) + " |",
                      "|---|" + "---|" * len(c.exponents)]
            for order, row in zip(c.sh_orders, rows):
                lines.append(f"| {order} | " + " | ".join(f"{v:.3f}" for v in row) + " |")
            lines.append("")
    return "\n".join(lines) + "\n"


CSV_COLUMNS = ("method", "label", "sh_order", "sh_window", "exponent", "mean_error_percent", "max_error_percent",
               "seconds_all_maps")


def csv_table(c: Comparison) -> str:
    """tables.csv: a row per method and exponent, with the SH order of that map (empty for methods without SH)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for name, errs in c.errors.items():
        record = c.method_parameters(name)
        orders = record.get("sh_order_per_exponent", [""] * len(c.exponents))
        for s, order, e in zip(c.exponents, orders, errs):
            writer.writerow([name, record["label"], order, record.get("sh_window", ""), _fmt_exponent(s),
                             f"{e['mean']:.6g}", f"{e['max']:.6g}", f"{c.seconds[name]:.4g}"])
    return out.getvalue()


def _save_figure(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")


def figure_grid(c: Comparison, path: Path) -> None:
    """Figure 6.4: rows = methods (with their SH orders), columns = exponents, each map tone-mapped on its own."""
    maps_grid({c.label(name): m for name, m in c.maps.items()}, c.exponents, path,
              f"Irradiance (s = 1) and reflection maps by method, {c.size}² angle maps")


def maps_grid_figure(maps: dict[str, np.ndarray], exponents: Sequence[float], title: str):
    """A row per method (its (E, N, N, 3) maps; the row's label may name its SH order), a column per exponent,
    each map tone-mapped on its own (so the colours show each map's shape, not radiance comparable across
    tiles: no colour bar can hold them all, and the title says so)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(maps)
    fig, axes = plt.subplots(len(names), len(exponents), figsize=(1.6 * len(exponents) + 1.6, 1.7 * len(names) + 0.5),
                             squeeze=False)
    for i, name in enumerate(names):
        for j, s in enumerate(exponents):
            ax = axes[i, j]
            ax.imshow(tonemap_preview(maps[name][j]))
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(f"s = {_fmt_exponent(s)}", fontsize=9)
            if j == 0:  # horizontal, a long label wrapped before its parenthesis: rows never overlap
                ax.set_ylabel(name.replace(" (", "\n("), fontsize=8, rotation=0, ha="right", va="center", labelpad=6)
    fig.suptitle(f"{title}\ncolumns: Phong exponent s; each map tone-mapped on its own (Reinhard, sRGB): "
                 "compare shapes, not brightness", fontsize=9)
    fig.tight_layout()
    return fig


def maps_grid(maps: dict[str, np.ndarray], exponents: Sequence[float], path: Path, title: str) -> None:
    """maps_grid_figure written to path."""
    import matplotlib.pyplot as plt

    fig = maps_grid_figure(maps, exponents, title)
    _save_figure(fig, path)
    plt.close(fig)


MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">", "h")


def sh_order_figure(c: Comparison):
    """Mean error against SH order per exponent (a colour and a marker each), stable Y_lm (solid, filled) and
    thesis-faithful factorials (dashed, hollow), on log axes; the legend beside the axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullFormatter

    fig, ax = plt.subplots(figsize=(8.5, 4.8))
    colours = plt.cm.tab10(np.arange(len(c.exponents)) % 10)
    handles = []
    for k, s in enumerate(c.exponents):
        marker = MARKERS[k % len(MARKERS)]
        for mode, style in (("stable", "-"), ("faithful", "--")):
            rows = c.sh_error_by_order.get(mode)
            if rows:
                ax.plot(c.sh_orders, [max(r[k], 1e-6) for r in rows], style, color=colours[k], marker=marker,
                        ms=5 if mode == "stable" else 8, mfc=colours[k] if mode == "stable" else "none",
                        lw=1.5 if mode == "stable" else 1.0)
        handles.append(Line2D([], [], color=colours[k], marker=marker, label=f"s = {_fmt_exponent(s)}"))
    handles += [Line2D([], [], color="black", ls="-", marker="o", label="stable Y_lm"),
                Line2D([], [], color="black", ls="--", marker="o", mfc="none", ms=8, label="factorial Y_lm\n(Alg. 2.5/2.6)")]
    if "sh" in c.errors and c.sh_orders:  # where the tables' sh row sits on this curve
        ax.axvline(c.params.sh_order, color="tab:gray", lw=0.8, ls=":")
        handles.append(Line2D([], [], color="tab:gray", ls=":", label=f"tables' {c.label('sh')}"))
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(c.sh_orders, [str(o) for o in c.sh_orders])
    ax.xaxis.set_minor_formatter(NullFormatter())  # the orders themselves are the ticks
    ax.set_xlabel("SH order L (bands 0..L-1)")
    ax.set_ylabel("mean error against accurate (%)")
    ax.set_title(f"sh maps against SH order, plain truncation ({c.size}² angle map)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), title="Phong exponent",
              title_fontsize=8)
    return fig


def sh_order_plot(c: Comparison, path: Path) -> None:
    import matplotlib.pyplot as plt

    fig = sh_order_figure(c)
    _save_figure(fig, path)
    plt.close(fig)


def write_comparison(c: Comparison, out_dir: Path) -> list[Path]:
    """tables.md, tables.json, tables.csv, methods.png and sh_order.png in out_dir; returns the paths."""
    paths = [out_dir / "tables.md", out_dir / "tables.json", out_dir / "tables.csv"]
    write_text_atomic(paths[0], markdown_tables(c))
    write_text_atomic(paths[1], json.dumps(c.to_json(), indent=2) + "\n")
    write_text_atomic(paths[2], csv_table(c))
    if c.maps:
        paths.append(out_dir / "methods.png")
        figure_grid(c, paths[-1])
    if c.sh_orders:
        paths.append(out_dir / "sh_order.png")
        sh_order_plot(c, paths[-1])
    return paths


def plot_maps_vs_truth(maps: MapSet, truth: MapSet, path: Path) -> None:
    """Per exponent: the map from the captured probe, the truth's (both tone-mapped on one scale, so that they
    compare), and the per-texel relative error (metrics.relative_error, mean over RGB, %) with a colour bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    exponents = [s for s in maps.exponents if s in truth.maps]
    fig, axes = plt.subplots(3, len(exponents), figsize=(1.9 * len(exponents) + 1.2, 6.0), dpi=100, squeeze=False)
    errors = []
    for j, s in enumerate(exponents):
        a, b = truth.maps[s], maps.maps[s]
        inside = a.sum(axis=-1) > 0
        both = tonemap_preview(np.concatenate([b, a], axis=1))
        n = a.shape[1]
        err = np.full(a.shape[:2], np.nan)
        err[inside] = 100 * relative_error(a[inside], b[inside]).mean(axis=-1)
        errors.append(err)
        for i, (image, label) in enumerate(((both[:, :n], "captured"), (both[:, n:], "truth"))):
            axes[i, j].imshow(image)
            if j == 0:
                axes[i, j].set_ylabel(label, fontsize=9)
        axes[0, j].set_title("irradiance" if s == 1 else f"s = {s:g}", fontsize=9)
    top = max(1.0, float(np.nanpercentile(np.concatenate([e[np.isfinite(e)] for e in errors]), 99)))
    for j, err in enumerate(errors):
        shown = axes[2, j].imshow(err, cmap="magma", vmin=0.0, vmax=top)
        axes[2, j].set_xlabel(f"mean {np.nanmean(err):.2f} %", fontsize=8)
    axes[2, 0].set_ylabel("error", fontsize=9)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(shown, ax=axes[2, :].tolist(), fraction=0.02, pad=0.01, label="relative error (%)")
    fig.suptitle(f"{maps.method} maps from the captured probe against the true environment's (error: the colour "
                 "bar's top is the 99th percentile)", fontsize=10)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    plt.close(fig)


def maps_figures(maps: dict[str, MapSet], truth_maps: dict[str, MapSet], folder: Path) -> None:
    """A run's maps drawn into folder: maps.png (every method's, maps_grid) and vs_truth_<method>.png per method
    with the true environment's maps beside it (plot_maps_vs_truth)."""
    exponents = next(iter(maps.values())).exponents
    maps_grid({method_label(name, MapParameters(), exponents): np.stack([m[s] for s in exponents]) for name, m in maps.items()},
              exponents, folder / "maps.png", "Irradiance (s = 1) and reflection maps baked from the captured probe")
    for name, truth in truth_maps.items():
        plot_maps_vs_truth(maps[name], truth, folder / f"vs_truth_{name}.png")
