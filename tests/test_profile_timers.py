"""GL timer readings that are no time (0, 2^32 - 1 or more, negative, unreadable) are dropped and counted,
never reported as times: in the loop's records, the profile (profile.json, profile.md, the trace) and
metrics.json's step_gl_ms, with n/a where a step has no valid reading."""

import json

import numpy as np
import pytest

from arsim.core.gl import TIMER_CLAMPED_NS, query_ms, timer_ms
from arsim.evaluate.profile import ProfileRun, markdown, step_gl_figures, write_profile
from arsim.render.loop import FrameLoop, FrameRecord

CLAMPED = 2**32 - 1


def test_the_rule():
    assert TIMER_CLAMPED_NS == CLAMPED
    assert timer_ms(2_500_000) == (2.5, None)
    assert timer_ms(np.uint32(1_000_000)) == (1.0, None)
    assert timer_ms(1) == (1e-6, None)
    assert timer_ms(CLAMPED - 1) == ((CLAMPED - 1) / 1e6, None)
    assert timer_ms(0) == (None, "zero")
    assert timer_ms(CLAMPED) == (None, "clamped")
    assert timer_ms(2**40) == (None, "clamped")
    assert timer_ms(-5) == (None, "negative")
    for bad in (None, float("nan"), float("inf"), "12", True):
        assert timer_ms(bad) == (None, "unavailable")


class FakeQuery:
    """A timer query whose readings are given in turn; None: reading it raises, as a driver's error."""

    def __init__(self, readings):
        self.readings = iter(readings)
        self.reading = None

    def __enter__(self):
        self.reading = next(self.readings)
        return self

    def __exit__(self, *exc):
        return False

    @property
    def elapsed(self):
        if self.reading is None:
            raise RuntimeError("query result not available")
        return self.reading


class FakeContext:
    def __init__(self, readings):
        self.timer = FakeQuery(readings)

    def query(self, time=False):
        assert time
        return self.timer

    def finish(self):
        pass


def test_query_ms_reads_an_unreadable_query_as_unavailable():
    q = FakeQuery([None])
    with q:
        pass
    assert query_ms(q) == (None, "unavailable")


# Per frame, the readings of background and objects (ns): 0 and 2^32 - 1 among valid ones; tone_mapping's
# readings are all 0 (no valid one: n/a).
BACKGROUND = [2_000_000, 0, 4_000_000, 3_000_000, CLAMPED]
OBJECTS = [CLAMPED, 5_000_000, 7_000_000, 0, 6_000_000]


def _records():
    readings = [v for frame in zip(BACKGROUND, OBJECTS, [0] * 5) for v in frame]
    loop = FrameLoop(FakeContext(readings), None, None)
    loop.origin = 0.0
    records = []
    for k in range(5):
        record = FrameRecord(k, 40.0 * k)
        for name in ("background", "objects", "tone_mapping"):
            loop._timed(record, name, lambda: None)
        records.append(record)
    return records


def test_the_loop_keeps_only_times_and_says_why_it_dropped_the_others():
    records = _records()
    assert [r.gl_ms.get("background") for r in records] == [2.0, None, 4.0, 3.0, None]
    assert [r.gl_dropped.get("background") for r in records] == [None, "zero", None, None, "clamped"]
    assert [r.gl_ms.get("objects") for r in records] == [None, 5.0, 7.0, None, 6.0]
    assert all("tone_mapping" not in r.gl_ms and r.gl_dropped["tone_mapping"] == "zero" for r in records)
    assert all(set(r.cpu_ms) == {"background", "objects", "tone_mapping"} for r in records)  # (the CPU times all kept)


def test_the_profile_excludes_and_counts_the_dropped_readings(tmp_path):
    run = ProfileRun("8", "accurate", 33.3, _records())
    steps = run.summary()["steps"]
    assert steps["background"]["gl"]["max"] == 4.0 and steps["background"]["gl"]["frames"] == 3
    assert steps["background"]["gl"]["p50"] == 3.0
    assert steps["objects"]["gl"]["max"] == 7.0 and steps["objects"]["gl"]["p50"] == 6.0  # not 4294.967
    assert steps["background"]["gl_dropped"] == {"clamped": 1, "zero": 1}
    assert steps["objects"]["gl_dropped"] == {"clamped": 1, "zero": 1}
    assert steps["tone_mapping"]["gl"] == {} and steps["tone_mapping"]["gl_dropped"] == {"zero": 5}
    assert steps["track"]["gl_dropped"] == {}
    md = markdown([run])
    row = next(line for line in md.splitlines() if line.startswith("| tone_mapping |"))
    assert row.count("n/a") == 4 and "0.000" not in row.split("|", 6)[-1]
    objects = next(line for line in md.splitlines() if line.startswith("| objects |"))
    assert "4294.967" not in objects and "| 7.000 |" in objects
    assert "objects 2 of 5 (1 clamped, 1 zero)" in md and "tone_mapping 5 of 5 (5 zero)" in md
    assert "2^32 - 1 ns" in md  # why, in words
    write_profile([run], tmp_path)
    summary = json.loads((tmp_path / "profile.json").read_text())["runs"][0]
    assert summary["steps"]["objects"]["gl_dropped"] == {"clamped": 1, "zero": 1}
    events = [e for e in json.loads((tmp_path / "trace.json").read_text())["traceEvents"] if e.get("name") == "objects"]
    assert [e["args"]["gl_ms"] for e in events] == [None, 5.0, 7.0, None, 6.0]
    assert [e["args"].get("gl_dropped") for e in events] == ["clamped", None, None, "zero", None]
    assert (tmp_path / "timeline.png").stat().st_size > 10_000


def test_metrics_step_gl_ms_is_the_median_of_the_times_and_n_a_where_none():
    figures = step_gl_figures(_records())
    assert figures["step_gl_ms"] == {"background": 3.0, "objects": 6.0, "tone_mapping": None}
    assert figures["step_gl_dropped"] == {"background": {"clamped": 1, "zero": 1}, "objects": {"clamped": 1, "zero": 1},
                                          "tone_mapping": {"zero": 5}}
    assert step_gl_figures([]) == {"step_gl_ms": {}, "step_gl_dropped": {}}


@pytest.mark.parametrize("readings, expected", [([0], (None, "zero")), ([CLAMPED], (None, "clamped")),
                                                ([3_000_000], (3.0, None))])
def test_the_loop_baker_drops_its_invalid_readings(readings, expected):
    """The bake's own timer query (LoopBaker): its reading kept as a time only when valid, its GL total over those."""
    from arsim.core.gl import create_gl_context
    from arsim.render.baking import BakeSettings, LoopBaker

    ctx = create_gl_context()
    probe = np.ones((16, 16, 3), np.float32)
    baker = LoopBaker(probe, [1.0], BakeSettings("accurate", tile=8), ctx)
    baker.query = FakeQuery(readings)
    baker.step(1000.0)
    assert (baker.last_gl_ms, baker.last_gl_dropped) == expected
    assert baker.gl_ms_total == (expected[0] or 0.0)
    baker.release()


def test_a_reading_under_a_microsecond_is_not_shown_as_zero():
    """llvmpipe's readings of a pass it rasterises outside the query can be ~20 ns: valid (not 0), and shown so."""
    loop = FrameLoop(FakeContext([20, 21, 19]), None, None)
    loop.origin = 0.0
    records = []
    for k in range(3):
        records.append(FrameRecord(k, 40.0 * k))
        loop._timed(records[-1], "background", lambda: None)
    row = next(line for line in markdown([ProfileRun("8", "accurate", 33.3, records)]).splitlines()
               if line.startswith("| background |"))
    assert row.split(" | ")[5:9] == ["2.0e-05", "2.1e-05", "2.1e-05", "2.1e-05"] and "0.000" not in row
