"""The figures arsim writes: each series, axis label, unit, legend and colour bar a reader needs, checked on the
matplotlib figure before it is saved."""

import csv
import io
import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from pathlib import Path  # noqa: E402

from arsim.lighting.methods import MapParameters  # noqa: E402
from arsim.sensors.recording import Recording  # noqa: E402


def colorbar_labels(fig) -> list[str]:
    """The labels of the figure's colour bars (vertical or horizontal)."""
    return [ax.get_ylabel() or ax.get_xlabel() for ax in fig.axes if ax.get_label() == "<colorbar>"]


def _recording(bracket: str | None, frames: int = 30) -> Recording:
    """A recording's frames only (what the exposure figure reads): the metered exposure rises, the bracketed
    frames sit 7 and 14 EV below it."""
    offsets = [0.0, -7.0, -14.0] if bracket else [0.0]
    rows = []
    for k in range(frames):
        metered_s = 1e-3 * (1 + k // len(offsets))
        rows.append({"t_ns": int(k * 1e9 / 30), "exposure_ns": int(round(1e9 * metered_s * 2.0 ** offsets[k % len(offsets)])),
                     "iso": 100.0, "file": f"frames/{k:06d}.png"})
    meta = {"scenario_toml": bracket} if bracket else {}
    return Recording(folder=Path("rec"), meta=meta, frames=rows, burst=[], imu={}, orientation=(np.zeros(1), Rotation.identity(1)),
                     groundtruth=None)


def test_exposure_figure_shows_the_metered_exposure_and_each_bracket_offset_as_its_own_series():
    from arsim.evaluate.recording_plots import exposure_figure

    rec = _recording("[capture]\nbracket_ev = [0.0, -7.0, -14.0]\n")
    fig = exposure_figure(rec)
    top = fig.axes[0]
    labels = [line.get_label() for line in top.get_lines()]
    assert labels == ["metered (0 EV): 1 frame in 3", "bracket -7 EV: 1 frame in 3", "bracket -14 EV: 1 frame in 3"]
    metered = top.get_lines()[0]
    # the metered series holds only the metered frames: a line over time, not a band alternating with the bracket
    np.testing.assert_allclose(metered.get_ydata(), [1.0 * (1 + k) for k in range(10)], rtol=1e-6)
    np.testing.assert_allclose(top.get_lines()[2].get_ydata(), metered.get_ydata() * 2.0**-14, rtol=1e-3)
    assert top.get_yscale() == "log" and "ms" in top.get_ylabel()
    assert [ax.get_ylabel() for ax in fig.axes[1:]] == ["exposure time (ms)", "ISO"]
    assert fig.axes[-1].get_xlabel() == "time (s)"
    assert top.get_legend() is not None
    plt.close(fig)
    # a recording without a scenario (a camera's own stream): every frame metered, one series
    fig = exposure_figure(_recording(None))
    assert [line.get_label() for line in fig.axes[0].get_lines()] == ["metered (0 EV)"]
    assert len(fig.axes[0].get_lines()[0].get_ydata()) == 30
    plt.close(fig)


def _comparison():
    from arsim.evaluate.compare_methods import Comparison

    exponents = [1.0, 80.0, 1280.0]
    errors = {name: [{"mean": 0.1 * (k + 1), "max": 1.0 * (k + 1)} for k in range(3)] for name in ("sh", "fast", "sht", "mipmap")}
    c = Comparison(32, exponents, 100, 0.1, errors=errors, seconds={n: 0.5 for n in errors},
                   sh_orders=[3, 5, 10, 20], params=MapParameters(sh_order=10, sh_window="hann"))
    c.sh_error_by_order = {mode: [[10.0 / o * (k + 1) for k in range(3)] for o in c.sh_orders] for mode in ("stable", "faithful")}
    c.maps = {name: np.ones((3, 8, 8, 3), np.float32) for name in ("accurate", *errors)}
    return c


def test_compare_methods_tables_name_every_sh_based_methods_order_and_window():
    from arsim.evaluate.compare_methods import csv_table, markdown_tables
    from arsim.lighting.fast import order_for_exponent
    from arsim.lighting.sht import bands_for_exponent

    c = _comparison()
    fast_orders = [order_for_exponent(s) for s in c.exponents]
    sht_orders = [bands_for_exponent(s) for s in c.exponents]
    assert c.label("sh") == "sh (order 10, window hann)"
    assert c.label("fast") == f"fast (SH order {min(fast_orders)}-{max(fast_orders)} by exponent)"
    assert c.label("sht") == f"sht (SH order {min(sht_orders)}-{max(sht_orders)} by exponent)"
    assert c.label("mipmap") == "mipmap"
    md = markdown_tables(c)
    assert md.count("| sh (order 10, window hann) |") == 4  # mean, max, time and the order of each map
    assert "| fast (SH order " in md and "| sht (SH order " in md
    assert "| fast (SH order 64-" + str(max(fast_orders)) + " by exponent) | " + " | ".join(map(str, fast_orders)) + " |" in md
    rows = list(csv.DictReader(io.StringIO(csv_table(c))))
    assert len(rows) == 4 * 3
    sh_rows = [r for r in rows if r["method"] == "sh"]
    assert [r["sh_order"] for r in sh_rows] == ["10"] * 3 and {r["sh_window"] for r in sh_rows} == {"hann"}
    assert [int(r["sh_order"]) for r in rows if r["method"] == "fast"] == fast_orders
    assert [int(r["sh_order"]) for r in rows if r["method"] == "sht"] == sht_orders
    assert {r["sh_order"] for r in rows if r["method"] == "mipmap"} == {""}
    record = json.loads(json.dumps(c.to_json()))["methods"]
    assert record["sh"] == {"label": "sh (order 10, window hann)", "sh_order_per_exponent": [10, 10, 10],
                            "sh_window": "hann", "sh_faithful": False}
    assert record["sht"]["sh_order_per_exponent"] == sht_orders and "sh_order_per_exponent" not in record["mipmap"]


def test_the_maps_grid_labels_its_rows_with_the_sh_orders():
    from arsim.evaluate.compare_methods import maps_grid_figure

    c = _comparison()
    fig = maps_grid_figure({c.label(n): m for n, m in c.maps.items()}, c.exponents, "maps")
    row_labels = [ax.get_ylabel() for ax in fig.axes if ax.get_ylabel()]
    assert row_labels == ["accurate", "sh\n(order 10, window hann)", c.label("fast").replace(" (", "\n("),
                          c.label("sht").replace(" (", "\n("), "mipmap"]
    assert "tone-mapped on its own" in fig._suptitle.get_text()
    plt.close(fig)


def test_sh_order_figure_tells_the_exponents_apart_on_log_axes_with_the_legend_off_the_data():
    from arsim.evaluate.compare_methods import sh_order_figure

    c = _comparison()
    fig = sh_order_figure(c)
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    stable = [line for line in ax.get_lines() if line.get_linestyle() == "-"]
    assert len(stable) == 3
    assert len({tuple(line.get_color()) for line in stable}) == 3 and len({line.get_marker() for line in stable}) == 3
    legend = ax.get_legend()
    texts = [t.get_text() for t in legend.get_texts()]
    assert texts[:3] == ["s = 1", "s = 80", "s = 1280"] and "tables' sh (order 10, window hann)" in texts
    fig.canvas.draw()
    assert legend.get_window_extent().x0 >= ax.get_window_extent().x1  # beside the axes, covering no curve
    assert "order" in ax.get_xlabel() and "%" in ax.get_ylabel()
    plt.close(fig)


def test_the_bases_visual_figures_carry_colour_bars_with_units():
    from arsim.evaluate.compare_bases import VisualComparison, visual_figure

    rng = np.random.default_rng(0)
    reference = rng.uniform(0.5, 1.0, (16, 16, 3))
    v = VisualComparison(reference, {"sh 4": reference * 1.1, "h 6": reference * 0.95})
    fig = visual_figure(v, "errors", "plane")
    assert colorbar_labels(fig) == ["|E~ - E| / max E (%), mean of the channels"]
    errors = [im for ax in fig.axes if ax.get_label() != "<colorbar>" for im in ax.get_images()]
    assert errors[0].get_clim() == (0.0, 25.0)
    # the 10 % brighter tile's error map holds |1.1 E - E| / max E in percent, on the bar's scale
    np.testing.assert_allclose(errors[1].get_array(), 100 * 0.1 * reference.mean(axis=-1) / reference.max(), rtol=1e-6)
    plt.close(fig)
    fig = visual_figure(v, "tiles", "plane")
    assert len(colorbar_labels(fig)) == 1 and "irradiance" in colorbar_labels(fig)[0]
    plt.close(fig)


def test_probe_vs_truth_has_a_radiance_bar_and_an_error_bar_in_percent():
    from arsim.evaluate.capture_report import probe_vs_truth_figure

    truth = np.ones((16, 16, 3), np.float32)
    fig = probe_vs_truth_figure(truth * 1.05, truth)
    labels = colorbar_labels(fig)
    assert len(labels) == 2 and "radiance" in labels[0] and labels[1].endswith("(%)")
    error = fig.axes[2].get_images()[0].get_array()
    assert np.nanmax(error) == pytest.approx(5.0, rel=1e-3)  # 5 % too bright, in percent
    plt.close(fig)


def test_spheres_figure_names_its_columns_and_has_a_radiance_bar_per_column():
    from arsim.evaluate.estimates import sphere_figure

    spheres = np.zeros((3, 8, 8, 3))
    spheres[:, 2:6, 2:6] = np.array([1.0, 2.0, 4.0])[:, None, None, None]
    fig = sphere_figure({"truth": spheres, "capture": spheres * 0.5})
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    assert titles == ["diffuse (albedo 0.8)", "matte silver (Phong s = 32)", "mirror"]
    assert colorbar_labels(fig) == ["radiance (the light's units)"] * 3
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert [b.get_xlim()[1] for b in bars] == pytest.approx([1 / 0.9, 2 / 0.9, 4 / 0.9])  # each column's exposure
    plt.close(fig)
