"""The layout's rules, checked so that they stay true: data flows one way through the stages (no module
imports from a later stage), and the map methods' names live in one list that every consumer takes."""

import argparse
import ast
import dataclasses
from pathlib import Path

import pytest

import arsim
from arsim.core.errors import ArsimError
from arsim.lighting.methods import LOOP_METHODS, METHODS
from arsim.render.baking import BakeSettings
from arsim.scenario.sections import ProfileSection, RenderObjectSection, RenderSection

# The stages in the order data flows through them (README: Layout); a module may import its own stage and
# those before it. cli, __main__ and testing sit on top.
LAYERS = ["core", "lighting", "scenario", "sensors", ("capture", "tracking"), "estimate", "render", "evaluate", "run"]
RANK = {name: rank for rank, layer in enumerate(LAYERS) for name in ((layer,) if isinstance(layer, str) else layer)}
PACKAGE = Path(arsim.__file__).parent


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("arsim."):
            yield node.lineno, node.module
        elif isinstance(node, ast.Import):
            yield from ((node.lineno, a.name) for a in node.names if a.name.startswith("arsim."))


def test_no_stage_imports_a_later_one():
    stages = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert stages == set(RANK), f"a stage not in LAYERS (add it where it belongs): {sorted(stages ^ set(RANK))}"
    upward = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).parts
        if len(parts) == 1:  # cli.py, __main__.py, testing.py: on top of every stage
            continue
        source = parts[0]
        for line, module in _imports(path):
            target = module.split(".")[1]
            if target in RANK and target != source and RANK[target] >= RANK[source]:
                upward.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {module}")
    assert not upward, "\n".join(upward)


def test_the_check_sees_an_upward_import(tmp_path):
    """(The rule above would pass vacuously if _imports found nothing.)"""
    module = tmp_path / "m.py"
    module.write_text("from arsim.evaluate.diff import flip_map\nimport arsim.run.pipeline\n")
    assert [m for _, m in _imports(module)] == ["arsim.evaluate.diff", "arsim.run.pipeline"]


def _choices(section, name):
    return next(f for f in dataclasses.fields(section) if f.name == name).metadata["choices"]


def _cli_choices(command: str, option: str):
    parser = arsim.cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return tuple(next(a for a in sub.choices[command]._actions if option in a.option_strings).choices)


def test_every_consumer_takes_the_map_methods_from_one_list():
    import arsim.cli  # noqa: F401 (build_parser)

    names = tuple(METHODS)
    assert _choices(RenderSection, "method") == names
    assert _choices(RenderSection, "methods") == names
    assert _choices(RenderObjectSection, "method") == ("",) + names
    assert set(_cli_choices("bake", "--method")) == set(names)
    assert set(_cli_choices("render", "--method")) == set(names)
    # what the frame loop can bake: the methods that say so, in the schema, the CLI and the baker alike
    assert LOOP_METHODS == tuple(n for n, m in METHODS.items() if m.in_loop) and LOOP_METHODS
    assert _choices(ProfileSection, "bake") == LOOP_METHODS
    assert _cli_choices("profile", "--bake") == LOOP_METHODS
    for name in names:
        if name in LOOP_METHODS:
            BakeSettings(name).check(64)
        else:
            with pytest.raises(ArsimError, match="cannot run in the frame loop"):
                BakeSettings(name).check(64)


def test_each_stage_declares_its_public_names_and_they_resolve():
    import importlib

    for stage in RANK:
        package = importlib.import_module(f"arsim.{stage}")
        assert package.__all__, stage
        for name in package.__all__:
            assert getattr(package, name) is not None, f"arsim.{stage}.{name}"
