"""`arsim batch`: two small scenarios in parallel processes and on a Ray head started on this machine give
the same summary; against baselines, a changed scenario is a regression; bad input in one line."""

import json
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
    assert summary["regressions"] == ["two"]
    assert "REGRESSION" in (root / "against" / "summary.md").read_text()


def test_batch_refuses_bad_input_in_one_line(scenarios, tmp_path):
    root, paths = scenarios
    (tmp_path / "broken.toml").write_text("[run]\nseed = -1\n")
    assert_one_line_error(arsim("batch", paths[0], tmp_path / "broken.toml", "-o", tmp_path / "o"), "broken.toml")
    assert_one_line_error(arsim("batch", paths[0], "-o", tmp_path / "o", "--ray", "127.0.0.1:1"), "no Ray head answers")
