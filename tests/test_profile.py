"""Step 3 and the profiler: `arsim profile` end to end on a short AR path (trace-event JSON valid and equal
to profile.md, the sweep table, the progress frames), the baked maps taking over when complete, black
tiles in the progress display while baking, and bad input refused in one line."""

import json
import re

import numpy as np
import pytest

from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import extend_beyond_rim, to_layout
from arsim.lighting.accurate import accurate_maps
from arsim.lighting.mipmap import mipmap_maps
from arsim.render.baking import BakeSettings, LoopBaker
from arsim.render.loop import FrameLoop, FrameRecord
from arsim.lighting.mapset import MapSet
from arsim.render.renderer import Renderer, overlay_image
from tests.conftest import ENVMAPS
from tests.test_cli import arsim, assert_one_line_error
from tests.test_render_session import SESSION

EXPONENTS = [1.0, 80.0]


@pytest.fixture(scope="module")
def probe():
    return to_layout(read_hdr(ENVMAPS[1]), "anglemap", 16)


def test_the_baked_maps_replace_the_ones_in_use_when_complete(probe):
    ctx = create_gl_context()
    renderer = Renderer(CameraIntrinsics.from_fov(64, 48, 60.0), MapSet.of("mipmap", EXPONENTS, mipmap_maps(probe, EXPONENTS)), ctx,
                        method="mipmap")
    baker = LoopBaker(probe, EXPONENTS, BakeSettings("accurate", tile=8), ctx)
    loop = FrameLoop(ctx, None, renderer, baker=baker)

    def held(s):
        texture = renderer.maps["mipmap", s]
        return np.frombuffer(texture.read(), np.float32).reshape(texture.height, texture.width, texture.components)[..., :3]

    before = {s: held(s).copy() for s in EXPONENTS}
    steps = 0
    while not loop.baked_in_use:
        loop._bake(FrameRecord(steps, 0.0))
        steps += 1
        if not loop.baked_in_use:  # meanwhile the objects keep the MIP-mapping maps
            assert all(np.array_equal(held(s), before[s]) for s in EXPONENTS)
    assert steps == 4  # a 16 x 16 map in tiles of 8: one per frame
    for s, reference in zip(EXPONENTS, accurate_maps(probe, EXPONENTS)):
        expected = extend_beyond_rim(reference)
        np.testing.assert_allclose(held(s), expected, rtol=1e-3, atol=1e-7)


@pytest.mark.parametrize("method", ["accurate", "sh"])
def test_auto_bakes_every_tile(method):
    """Auto splits tiles (accurate: into input ranges over frames; SH: into quadrants); when it is done,
    every texel equals a bake of the whole map in one call."""
    from arsim.lighting.gl_bake import gl_accurate_maps, gl_sh_maps

    ctx = create_gl_context()
    probe = to_layout(read_hdr(ENVMAPS[1]), "anglemap", 128)
    baker = LoopBaker(probe, EXPONENTS, BakeSettings(method, tile=None, sh_order=8), ctx)
    baker.warm_up()
    frames = 0
    while not baker.done:
        baker.step(30.0)
        frames += 1
        assert frames < 5000
    whole = (gl_accurate_maps(probe, EXPONENTS, ctx=ctx) if method == "accurate" else
             gl_sh_maps(probe, EXPONENTS, 8, ctx=ctx))
    np.testing.assert_allclose(baker.maps(), whole, rtol=1e-4, atol=1e-6 * np.abs(whole).max())
    baker.release()


def test_the_progress_display_shows_black_tiles_while_baking(probe):
    ctx = create_gl_context()
    camera = CameraIntrinsics.from_fov(320, 240, 60.0)
    renderer = Renderer(camera, MapSet.of("mipmap", EXPONENTS, mipmap_maps(probe, EXPONENTS)), ctx)
    baker = LoopBaker(probe, EXPONENTS, BakeSettings("accurate", tile=8), ctx)
    baker.step(1000.0)  # the top-left quarter of the map
    renderer.background_pass(np.full((240, 320, 3), 128, np.uint8))
    renderer.overlay_pass(["baking"], baker.thumbnail)
    out = renderer.read_output()
    margin, text_h = 240 // 90, overlay_image(["baking"], 240).shape[0]
    side = 240 // 4
    thumb = out[2 * margin + text_h:2 * margin + text_h + side, margin:margin + side]
    quarter = side // 2
    assert (thumb[:quarter - 2, :quarter - 2].max(axis=-1) > 0).mean() > 0.6  # the baked tile (its disk part)
    assert (thumb[quarter + 2:, :] == 0).all() and (thumb[:, quarter + 2:] == 0).all()  # the others black
    baker.release()


def _table(md: str, heading: str) -> dict:
    """The step rows of one run's table in profile.md: name -> the eight numbers (CPU, GL p50/p95/p99/max)."""
    section = md.split(heading, 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 10 and re.fullmatch(r"[\d.]+", cells[1] or "x"):
            rows[cells[0]] = [float(c) if c and c != "n/a" else None for c in cells[1:9]]
    return rows


def test_profile_end_to_end_writes_a_valid_trace_equal_to_its_tables(tmp_path):
    (tmp_path / "s.toml").write_text(SESSION.format(env=ENVMAPS[1].as_posix()).split("[[render.objects]]")[0])
    r = arsim("profile", tmp_path / "s.toml", "-o", tmp_path / "out", "--map-size", "16", "--sweep", "8,auto",
              "--max-frames", "300")
    assert r.returncode == 0, r.stderr
    out = tmp_path / "out"
    md = (out / "profile.md").read_text()
    summary = json.loads((out / "profile.json").read_text())
    assert [run["policy"] for run in summary["runs"]] == ["8", "auto"]
    assert "| 8 | 4 |" in md  # the sweep table: 16 x 16 maps in tiles of 8 take four frames
    for run in summary["runs"]:
        assert run["bake"]["completed"]
        label = run["policy"]
        trace = json.loads((out / f"trace_{label}.json").read_text())
        events = trace["traceEvents"]
        # The trace-event format: complete events with name, ph, pid, tid, ts and dur in microseconds;
        # metadata naming the process and one track (thread) per step.
        tracks = {e["tid"]: e["args"]["name"] for e in events if e["ph"] == "M" and e["name"] == "thread_name"}
        assert set(tracks.values()) >= {"frame", "bake", "background", "objects", "tone_mapping", "overlay", "track"}
        complete = [e for e in events if e["ph"] == "X"]
        assert complete and all({"name", "pid", "tid", "ts", "dur"} <= set(e) and e["dur"] >= 0 and e["tid"] in tracks
                                for e in complete)
        # Its numbers are profile.md's.
        table = _table(md, f"## Tile policy {label} ")
        for step in ("bake", "background", "overlay"):
            cpu = np.array([e["dur"] / 1000 for e in complete if e["name"] == step])
            # (GL: the readings that are times; the others dropped, with why, never a time)
            gl = np.array([e["args"]["gl_ms"] for e in complete if e["name"] == step and e["args"]["gl_ms"] is not None])
            # (or a frame the bake drew nothing in: no reading)
            assert all(e["args"].get("gl_dropped") in {"zero", "clamped", "negative", "unavailable"}
                       or (step == "bake" and e["args"]["tiles"] == 0 and "gl_dropped" not in e["args"])
                       for e in complete if e["name"] == step and e["args"]["gl_ms"] is None)
            assert ((gl > 0) & (gl < 4294.967)).all()
            expected = [np.percentile(cpu, p) for p in (50, 95, 99)] + [cpu.max()]
            if gl.size:
                expected += [np.percentile(gl, p) for p in (50, 95, 99)] + [gl.max()]
            else:  # (no reading a time: n/a)
                assert table[step][4:] == [None] * 4
            np.testing.assert_allclose(table[step][:len(expected)], expected, atol=6e-4)
        frames = np.array([e["dur"] / 1000 for e in complete if e["cat"] == "frame"])
        assert run["misses"] == int((frames > run["budget_ms"]).sum())
    assert (out / "timeline_auto.png").stat().st_size > 10_000
    assert sorted(p.name.split("_frame")[0] for p in (out / "tile_auto" / "frames").glob("*.png")) == \
        ["bake_025pct", "bake_050pct", "bake_100pct"]


def test_profile_refuses_bad_input_in_one_line(tmp_path):
    out = tmp_path / "out"
    assert_one_line_error(arsim("profile", "-o", out, "--budget-ms", "0"), "--budget-ms")
    assert_one_line_error(arsim("profile", "-o", out, "--tile", "48"), "does not divide")
    assert_one_line_error(arsim("profile", "-o", out, "--tile", "big"), "auto")
    assert_one_line_error(arsim("profile", "-o", out, "--sweep", ","), "no entries")
    assert not out.exists()
