"""The package imports in one direction (docs/architecture.md).

Between packages: each layer's package, imported alone in a fresh interpreter, must not pull in
a module of a higher layer. Inside a package: the files' imports of each other (at the top, in
a function, or for type checking only) form no circle, so that one file of a pair is always
the lower one (a circle like ``config.py`` <-> ``builders.py`` fails). A resume is one file's
business: of the trainer's files, only ``resume.py`` imports what a resume checks, cuts back
and restores."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

import s3rl_torchrl

# Lowest first; a package may import its own layer and the layers below it.
LAYERS = [
    ("envs", "transforms", "data"),
    ("modules",),
    ("objectives",),
    ("diagnostics",),
    ("algorithms",),
    ("hooks",),
    ("trainer",),
    ("report",),
    ("recipes",),
]
LAYER_OF = {package: level for level, packages in enumerate(LAYERS) for package in packages}
ROOT = Path(s3rl_torchrl.__file__).parent


def imported_packages(package: str) -> set[str]:
    """The s3rl_torchrl subpackages in sys.modules after importing every module of ``package``
    (its __init__ may not import them all), in a fresh interpreter."""
    code = f"""
import importlib, json, pkgutil, sys
import s3rl_torchrl.{package} as root
for info in pkgutil.walk_packages(root.__path__, root.__name__ + "."):
    importlib.import_module(info.name)
print(json.dumps(sorted({{m.split(".")[1] for m in sys.modules
                         if m.startswith("s3rl_torchrl.") and m.count(".") >= 1}})))
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    return set(json.loads(out.strip().splitlines()[-1]))


def test_every_subpackage_has_a_layer():
    import pkgutil

    packages = {m.name for m in pkgutil.iter_modules(s3rl_torchrl.__path__) if m.ispkg}
    assert packages == set(LAYER_OF)


@pytest.mark.parametrize("package", sorted(LAYER_OF, key=LAYER_OF.get))
def test_a_layer_imports_nothing_above_it(package):
    above = {p for p in imported_packages(package) if LAYER_OF.get(p, -1) > LAYER_OF[package]}
    assert not above, f"s3rl_torchrl.{package} imports higher layers: {sorted(above)}"


# ------------------------------------------------------------------------------ inside a package
def sibling_imports(path: Path, package: str, siblings: set[str]) -> set[str]:
    """The files of ``package`` that the file at ``path`` imports, anywhere in it (at the top,
    in a function, under ``if TYPE_CHECKING:``); ``__init__`` for the package itself."""
    prefix = f"s3rl_torchrl.{package}"
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = node.module if not node.level else f"{prefix}.{node.module or ''}".rstrip(".")
            if module == prefix:  # `from <package> import x`: x is a file, or __init__'s name
                found |= {a.name if a.name in siblings else "__init__" for a in node.names}
                continue
            modules = [module]
        else:
            continue
        for module in modules:
            if module == prefix:
                found.add("__init__")
            elif module.startswith(prefix + "."):
                found.add(module[len(prefix) + 1 :].split(".")[0])
    found &= siblings
    found.discard(path.stem)
    return found


def import_graph(directory: Path, package: str) -> dict[str, set[str]]:
    files = {path.stem: path for path in directory.glob("*.py")}
    return {name: sibling_imports(path, package, set(files)) for name, path in files.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One circle of the directed graph (``[a, b, ..., a]``), or None."""
    state: dict[str, str] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node], _ = "open", stack.append(node)
        for target in sorted(graph.get(node, ())):
            if state.get(target) == "open":
                return stack[stack.index(target) :] + [target]
            if target not in state and (cycle := visit(target)):
                return cycle
        state[node], _ = "done", stack.pop()
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


@pytest.mark.parametrize("package", sorted(LAYER_OF, key=LAYER_OF.get))
def test_the_files_of_a_package_import_each_other_in_one_direction(package):
    cycle = find_cycle(import_graph(ROOT / package, package))
    assert cycle is None, f"s3rl_torchrl.{package}: {' -> '.join(f + '.py' for f in cycle)}"


def test_a_circle_through_a_type_checking_import_is_found(tmp_path):
    # The circle the issue named: config.py imported builders.py at its top, builders.py
    # imported config.py for type checking only.
    (tmp_path / "config.py").write_text("from s3rl_torchrl.trainer.builders import FAMILIES\n")
    (tmp_path / "builders.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n"
        "    from s3rl_torchrl.trainer.config import AlgoConfig\n"
    )
    (tmp_path / "loop.py").write_text("from s3rl_torchrl.trainer import builders, config\n")
    graph = import_graph(tmp_path, "trainer")
    assert graph == {"config": {"builders"}, "builders": {"config"}, "loop": {"builders", "config"}}
    assert find_cycle(graph) in (
        ["builders", "config", "builders"],
        ["config", "builders", "config"],
    )
    (tmp_path / "builders.py").write_text("import torch\n")
    assert find_cycle(import_graph(tmp_path, "trainer")) is None


def test_a_file_importing_its_own_package_is_a_circle(tmp_path):
    (tmp_path / "__init__.py").write_text("from s3rl_torchrl.hooks.labels import GradedLabels\n")
    (tmp_path / "labels.py").write_text("from s3rl_torchrl.hooks import TrainerHook\n")
    assert find_cycle(import_graph(tmp_path, "hooks")) == ["__init__", "labels", "__init__"]


# ------------------------------------------------------------------------------ resume
# What only trainer/resume.py uses (docs/architecture.md, "Resume"): the checks of a resumed
# config, the cut-back of the run's files, whether the envs can continue exactly. The loop
# calls Resume.read before it builds and Resume.restore once it has built.
RESUME_ONLY = {
    "RESUME_LOCKED",
    "check_compatible",
    "check_total_frames",
    "config_changes",
    "cut_back_to_checkpoint",
    "exact_restore_unsupported",
    "record_resume",
}


def imported_names(path: Path) -> set[str]:
    """The names a file imports from the package (``from s3rl_torchrl... import name``)."""
    return {
        alias.name
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("s3rl_torchrl")
        for alias in node.names
    }


def test_only_resume_py_checks_cuts_back_and_restores_a_resume():
    trainer = ROOT / "trainer"
    found = {
        path.name: sorted(imported_names(path) & RESUME_ONLY)
        for path in sorted(trainer.glob("*.py"))
        if path.name != "resume.py"
    }
    assert {name: names for name, names in found.items() if names} == {}
    assert "Resume" in imported_names(trainer / "loop.py")
    assert {"cut_back_to_checkpoint", "exact_restore_unsupported"} <= imported_names(
        trainer / "resume.py"
    )
