"""What a bare install gets: the commands need no test-only package, the wheel holds the bundled data, and
bundled scenarios are found by name from anywhere."""

import pkgutil
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

import arsim
from arsim.core.assets import assets_dir, bundled_scenarios, scenarios_dir
from arsim.scenario import ScenarioError, load_scenario
from tests.test_cli import arsim as run_arsim

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _names(requirements):
    return {r.split(">")[0].split("=")[0].split("[")[0].strip().lower() for r in requirements}


# Imported as modules: pytest's own package is _pytest; ray and hypothesis by their names.
TEST_ONLY = sorted((_names(PROJECT["optional-dependencies"]["test"]) - _names(PROJECT["dependencies"])) | {"_pytest"})

BLOCK = """
import importlib.abc, sys
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in {blocked!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked: a test-only package)")
sys.meta_path.insert(0, Block())
"""


def test_no_command_needs_a_test_only_package():
    """Every module of arsim but the pytest plugin imports with the test extra's packages absent (each
    command imports what it needs from these modules), and the command line answers."""
    modules = sorted(m.name for m in pkgutil.walk_packages(arsim.__path__, "arsim.") if m.name not in ("arsim.testing", "arsim.__main__"))
    assert len(modules) > 40 and "arsim.cli" in modules and "arsim.run.pipeline" in modules
    script = BLOCK.format(blocked=set(TEST_ONLY)) + f"""
import importlib
for name in {modules!r}:
    importlib.import_module(name)
from arsim.cli import main
sys.argv = ["arsim", "validate", "quick"]
raise SystemExit(main())
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert r.returncode == 0 and 'name = "quick"' in r.stdout, r.stderr
    # the check can fail: the plugin itself needs pytest
    r = subprocess.run([sys.executable, "-c", BLOCK.format(blocked=set(TEST_ONLY)) + "import arsim.testing"],
                       capture_output=True, text=True)
    assert r.returncode == 1 and "blocked: a test-only package" in r.stderr


def test_the_wheel_holds_the_bundled_data(tmp_path):
    """Built from a copy of the checkout, the wheel carries every asset and scenario, where assets_dir() and
    scenarios_dir() look for them."""
    src = tmp_path / "src"
    shutil.copytree(ROOT / "arsim", src / "arsim", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                        "-w", str(tmp_path / "dist"), str(src)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    (wheel,) = (tmp_path / "dist").glob("arsim-*.whl")
    inside = set(zipfile.ZipFile(wheel).namelist())
    package = Path(arsim.__file__).parent
    bundled = [p for d in (assets_dir(), scenarios_dir()) for p in d.rglob("*") if p.is_file()]
    assert len(bundled) >= 20
    for path in bundled:
        assert path.relative_to(package.parent).as_posix() in inside, path
    assert "arsim/scenario/default.toml" in inside and any(n.startswith("arsim/render/shaders/") for n in inside)
    shaders = [p for p in package.rglob("shaders/*") if p.is_file() and p.suffix != ".pyc"]
    assert len(shaders) >= 10
    for path in shaders:  # (every kind: a compute shader left out of package-data would fail only when installed)
        assert path.relative_to(package.parent).as_posix() in inside, path


def test_bundled_scenarios_by_name(tmp_path):
    names = bundled_scenarios()
    assert {"quick", "indoor", "night", "lost_tag"} <= set(names)
    assert load_scenario("indoor") == load_scenario(names["indoor"])
    with pytest.raises(ScenarioError, match="name a bundled scenario \\(bake_512, drifting_gyro"):
        load_scenario("kitchen")
    # a file of that name in the working folder comes first
    (tmp_path / "indoor").write_text('[run]\nname = "mine"\n')
    r = run_arsim("validate", "indoor", cwd=tmp_path)
    assert r.returncode == 0 and 'name = "mine"' in r.stdout, r.stderr
    r = run_arsim("validate", "night", cwd=tmp_path)
    assert r.returncode == 0 and 'name = "night"' in r.stdout and str(assets_dir()) in r.stdout, r.stderr
