"""`arsim batch`: two small scenarios in parallel processes and on a Ray head started on this machine give
the same summary; against baselines, a changed scenario is a regression; bad input in one line."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ENVMAPS
from tests.test_cli import arsim, assert_one_line_error
from tests.test_run import SMALL


@pytest.fixture(scope="module")
def scenarios(tmp_path_factory):
    root = tmp_path_factory.mktemp("batch")
    paths = []
    for name, exponent in (("one", 80.0), ("two", 20.0)):
        path = root / f"{name}.toml"
        path.write_text(SMALL.format(env=ENVMAPS[1].as_posix(), exponent=exponent).replace('name = "small"', f'name = "{name}"'))
        paths.append(path)
    return root, paths


@pytest.fixture(scope="module")
def local(scenarios):
    root, paths = scenarios
    r = arsim("batch", *paths, "-o", root / "local", "--workers", "2")
    assert r.returncode == 0, r.stdout + r.stderr
    return root / "local"


def test_a_local_batch_writes_one_summary_of_every_run(local):
    summary = json.loads((local / "summary.json").read_text())
    assert [s["name"] for s in summary["scenarios"]] == ["one", "two"]
    assert summary["failed"] == [] and summary["timing"]["backend"] == "local, 2 workers"
    for name in ("one", "two"):
        assert (local / name / "report" / "index.html").is_file()
    table = (local / "summary.md").read_text()
    assert "| one | ok |" in table and "| two | ok |" in table
    assert 'href="one/report/index.html"' in (local / "summary.html").read_text()


def test_the_ray_backend_gives_the_same_summary(scenarios, local):
    pytest.importorskip("ray")
    root, paths = scenarios
    ray = shutil.which("ray") or str(Path(sys.executable).parent / "ray")
    port = "6391"
    start = subprocess.run([ray, "start", "--head", f"--port={port}", "--num-cpus=2", "--include-dashboard=false"],
                           capture_output=True, text=True)
    assert start.returncode == 0, start.stdout + start.stderr
    try:
        r = arsim("batch", *paths, "-o", root / "ray", "--ray", f"127.0.0.1:{port}")
        assert r.returncode == 0, r.stdout + r.stderr
    finally:
        subprocess.run([ray, "stop", "--force"], capture_output=True)
    assert (root / "ray" / "summary.md").read_text() == (local / "summary.md").read_text()
    assert json.loads((root / "ray" / "summary.json").read_text())["timing"]["backend"].startswith("ray ")


def test_a_changed_scenario_is_a_regression_against_the_baselines(scenarios, local):
    root, paths = scenarios
    baselines = root / "baselines"
    for name in ("one", "two"):
        shutil.copytree(local / name / "frames", baselines / name / "frames")
    changed = root / "changed"
    changed.mkdir()
    for path in paths:
        text = path.read_text()
        (changed / path.name).write_text(text.replace("exponent = 20.0", "exponent = 5.0"))
    r = arsim("batch", changed / "one.toml", changed / "two.toml", "-o", root / "against", "--baselines", baselines,
              "--workers", "2")
    assert r.returncode == 1, r.stdout + r.stderr
    summary = json.loads((root / "against" / "summary.json").read_text())
    assert summary["regressions"] == ["two"] and summary["failed"] == []  # exit 1 with a failing diff: a regression
    assert "REGRESSION" in (root / "against" / "summary.md").read_text()


def test_batch_refuses_bad_input_in_one_line(scenarios, tmp_path):
    root, paths = scenarios
    (tmp_path / "broken.toml").write_text("[run]\nseed = -1\n")
    assert_one_line_error(arsim("batch", paths[0], tmp_path / "broken.toml", "-o", tmp_path / "o"), "broken.toml")
    assert_one_line_error(arsim("batch", paths[0], "-o", tmp_path / "o", "--ray", "127.0.0.1:1"), "no Ray head answers")


def test_a_run_that_crashes_is_a_failure_named_with_its_message(scenarios, tmp_path):
    # the run's process crashes (exit 1 with a traceback, as a bug would): a startup hook makes run_scenario
    # raise for the scenario named boom
    root, paths = scenarios
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(
        "import arsim.run.pipeline as p\n"
        "def boom(scenario, source, *a, **k):\n"
        "    raise RuntimeError('simulated crash in ' + source)\n"
        "p.run_scenario = boom\n")
    boom = tmp_path / "boom.toml"
    boom.write_text(paths[0].read_text().replace('name = "one"', 'name = "boom"'))
    root_dir = Path(__file__).resolve().parents[1]
    env = os.environ | {"PYTHONPATH": os.pathsep.join([str(hook), str(root_dir), os.environ.get("PYTHONPATH", "")])}
    r = arsim("batch", boom, "-o", tmp_path / "out", env=env)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "boom failed: RuntimeError: simulated crash" in r.stderr and "failed: boom" in r.stdout
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["failed"] == ["boom"] and summary["scenarios"][0]["ok"] is False
    assert "| boom | failed: RuntimeError: simulated crash" in (tmp_path / "out" / "summary.md").read_text()


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "-0.1"])
def test_a_gate_without_a_finite_tolerance_is_refused(scenarios, tmp_path, value):
    root, paths = scenarios
    for command in (["diff", ENVMAPS[0], ENVMAPS[0]], ["run", paths[0], "-o", tmp_path / "r", "--baseline", tmp_path],
                    ["batch", paths[0], "-o", tmp_path / "b", "--baselines", tmp_path]):
        r = arsim(*command, f"--max-flip={value}")
        assert_one_line_error(r, "--max-flip")
        assert not (tmp_path / "r").exists() and not (tmp_path / "b").exists()
