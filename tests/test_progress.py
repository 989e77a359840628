"""Progress where output is not a terminal: plain lines on stderr, one per stage start, at most one per 10 %
of its progress and one at its end, each with the elapsed time; a real command's log; ARSIM_PROGRESS."""

import io
import os
import re

import pytest

from arsim.core.errors import ArsimError
from arsim.core.progress import ProgressLines, progress_bar, progress_mode
from tests.test_cli import arsim, assert_one_line_error

LINE = re.compile(r"\[arsim\] (?P<stage>.+?): (?:(?P<pct>\d+) % \((?P<t>\d+\.\d) s\)(?:, .*)?|started|done \((?P<end>\d+\.\d) s\))$")


class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_lines_come_at_most_every_10_percent_with_the_elapsed_time():
    clock, out = FakeClock(), io.StringIO()
    lines = ProgressLines("2/6 capture", 200, stream=out, clock=clock)
    for k in range(1, 201):  # 200 updates, 0.5 % each, 0.25 s apart
        clock.now += 0.25
        lines.update(completed=k)
    lines.end()
    text = out.getvalue().splitlines()
    assert text[0] == "[arsim] 2/6 capture: started"
    assert text[1] == "[arsim] 2/6 capture: 10 % (5.0 s)"  # update 20 of 200, 20 x 0.25 s in
    assert text[-1] == "[arsim] 2/6 capture: done (50.0 s)"
    percents = [int(m) for m in re.findall(r": (\d+) % ", "\n".join(text))]
    assert percents == [10, 20, 30, 40, 50, 60, 70, 80, 90, 100]


def test_uneven_updates_never_give_lines_closer_than_10_percent():
    clock, out = FakeClock(), io.StringIO()
    lines = ProgressLines("maps", 1.0, stream=out, clock=clock)
    for f in (0.01, 0.05, 0.099, 0.12, 0.13, 0.2, 0.215, 0.5, 0.55, 0.59, 0.61, 0.99, 1.0):
        clock.now += 1.0
        lines.update(completed=f, description="maps: accurate")
    shown = [float(m) for m in re.findall(r": (\d+) % ", out.getvalue())]
    assert shown == [12, 50, 61, 99]  # (0.215 < 0.12 + 0.1; 1.0 < 0.99 + 0.1)
    assert all(b - a >= 10 for a, b in zip(shown, shown[1:]))
    assert out.getvalue().splitlines()[1] == "[arsim] maps: 12 % (4.0 s), accurate"  # the label's detail after


def test_every_update_gives_a_line_per_finished_run():
    clock, out = FakeClock(), io.StringIO()
    lines = ProgressLines("running 40 scenarios", 40, stream=out, clock=clock, every_update=True)
    for k in range(1, 41):
        lines.update(completed=k, description=f"running 40 scenarios: s{k} done")
    assert len(out.getvalue().splitlines()) == 41 and out.getvalue().splitlines()[-1].endswith("100 % (0.0 s), s40 done")


def test_progress_mode_reads_the_environment(monkeypatch):
    for value, mode in (("", "auto"), ("off", "off"), ("Lines", "lines"), (" auto ", "auto")):
        monkeypatch.setenv("ARSIM_PROGRESS", value)
        assert progress_mode() == mode
    monkeypatch.setenv("ARSIM_PROGRESS", "loud")
    with pytest.raises(ArsimError, match="ARSIM_PROGRESS='loud'"):
        progress_mode()


def test_progress_bar_off_prints_nothing_and_lines_print_on_failure(monkeypatch, capsys):
    monkeypatch.setenv("ARSIM_PROGRESS", "off")
    with progress_bar("quiet", 1.0) as update:
        update(completed=0.5)
    assert capsys.readouterr().err == ""
    monkeypatch.setenv("ARSIM_PROGRESS", "lines")
    with pytest.raises(ValueError), progress_bar("doomed", 1.0) as update:
        update(completed=0.3)
        raise ValueError
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "[arsim] doomed: started" and err[1].startswith("[arsim] doomed: 30 % (")
    assert re.fullmatch(r"\[arsim\] doomed: stopped \(\d+\.\d s\)", err[2])


SCENARIO = """
[run]
seed = 2
[environment]
probe_size = 64
[capture]
duration_s = 2.0
capture_size = 64
[device.camera]
width = 96
height = 72
[ar]
enabled = false
"""


def test_a_command_logs_each_stage_with_percentages_and_elapsed_times(tmp_path):
    """`arsim capture` (a 2 s sweep recorded, then captured) with stderr a file, not a terminal."""
    (tmp_path / "s.toml").write_text(SCENARIO)
    env = os.environ | {"ARSIM_PROGRESS": "auto"}  # (the suite turns it off)
    with open(tmp_path / "stderr.log", "w") as err:
        import subprocess
        import sys

        r = subprocess.run([sys.executable, "-m", "arsim", "capture", str(tmp_path / "s.toml"), "-o", str(tmp_path / "out")],
                           stdout=subprocess.PIPE, stderr=err, text=True, env=env)
    assert r.returncode == 0
    log = [line for line in (tmp_path / "stderr.log").read_text().splitlines() if line.startswith("[arsim]")]
    matches = [LINE.match(line) for line in log]
    assert all(matches), log
    stages = list(dict.fromkeys(m["stage"] for m in matches))
    assert stages == ["recording the capture sweep", "capturing"]
    for stage in stages:
        own = [m for m in matches if m["stage"] == stage]
        assert own[0].group(0).endswith("started") and own[-1]["end"] is not None
        percents = [int(m["pct"]) for m in own if m["pct"] is not None]
        times = [float(m["t"]) for m in own if m["t"] is not None] + [float(own[-1]["end"])]
        assert percents and percents[-1] >= 90, own  # it reports its progress up to the end
        assert all(b - a >= 9 for a, b in zip(percents, percents[1:])), percents  # at most every ~10 % (rounded)
        assert len(percents) <= 10
        assert times == sorted(times)
    assert "captured 61 frames" in r.stdout


def test_a_bad_progress_setting_is_refused_in_one_line(tmp_path):
    env = os.environ | {"ARSIM_PROGRESS": "loud"}
    assert_one_line_error(arsim("capture", tmp_path / "none.toml", "-o", tmp_path / "out", env=env), "ARSIM_PROGRESS")
    assert not (tmp_path / "out").exists()


def test_batch_logs_a_line_per_finished_run(tmp_path):
    """`arsim batch` with stderr not a terminal: a line per run as it finishes (here two runs that crash at once:
    a startup hook makes run_scenario raise), and the runs' own errors still what the summary names."""
    import subprocess
    import sys
    from pathlib import Path

    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(
        "import arsim.run.pipeline as p\n"
        "def boom(scenario, source, *a, **k):\n"
        "    raise RuntimeError('simulated crash')\n"
        "p.run_scenario = boom\n")
    for name in ("alpha", "beta"):
        (tmp_path / f"{name}.toml").write_text(f'[run]\nname = "{name}"\n')
    root = Path(__file__).resolve().parents[1]
    env = os.environ | {"ARSIM_PROGRESS": "auto",
                        "PYTHONPATH": os.pathsep.join([str(hook), str(root), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-m", "arsim", "batch", str(tmp_path / "alpha.toml"), str(tmp_path / "beta.toml"),
                        "-o", str(tmp_path / "out"), "--workers", "2"], capture_output=True, text=True, env=env)
    assert r.returncode == 1, r.stderr
    log = [line for line in r.stderr.splitlines() if line.startswith("[arsim]")]
    assert log[0] == "[arsim] running 2 scenarios: started"
    assert re.fullmatch(r"\[arsim\] running 2 scenarios: 50 % \(\d+\.\d s\), (alpha|beta) failed", log[1]), log
    assert re.fullmatch(r"\[arsim\] running 2 scenarios: 100 % \(\d+\.\d s\), (alpha|beta) failed", log[2]), log
    assert re.fullmatch(r"\[arsim\] running 2 scenarios: done \(\d+\.\d s\)", log[3]) and len(log) == 4, log
    assert "alpha failed: RuntimeError: simulated crash" in r.stderr  # (the run's last line, not a progress line)
