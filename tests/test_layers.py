"""The package's layers import downwards only (docs/architecture.md): each layer's package,
imported alone in a fresh interpreter, must not pull in a module of a higher layer."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

# Lowest first; a package may import its own layer and the layers below it.
LAYERS = [
    ("envs", "transforms", "data"),
    ("modules",),
    ("objectives",),
    ("diagnostics",),
    ("trainer",),
    ("report",),
    ("recipes",),
]
LAYER_OF = {package: level for level, packages in enumerate(LAYERS) for package in packages}


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

    import s3rl_torchrl

    packages = {m.name for m in pkgutil.iter_modules(s3rl_torchrl.__path__) if m.ispkg}
    assert packages == set(LAYER_OF)


@pytest.mark.parametrize("package", sorted(LAYER_OF, key=LAYER_OF.get))
def test_a_layer_imports_nothing_above_it(package):
    above = {p for p in imported_packages(package) if LAYER_OF.get(p, -1) > LAYER_OF[package]}
    assert not above, f"s3rl_torchrl.{package} imports higher layers: {sorted(above)}"
