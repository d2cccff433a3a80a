"""Packaging: the wheel holds one package with its configs and trains from any directory."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest
from setuptools import find_packages

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    from pip._vendor import tomli as tomllib

from s3rl_torchrl.recipes import config_dir

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_every_subpackage_is_in_the_package_list():
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = set(find_packages(str(ROOT), include=["s3rl_torchrl*"]))
    assert found - listed == set(), "add them to [tool.setuptools] packages in pyproject.toml"
    assert listed - found == {"s3rl_torchrl.configs"}  # configs/, mapped in package-dir
    assert PYPROJECT["tool"]["setuptools"]["package-dir"] == {"s3rl_torchrl.configs": "configs"}
    scripts = PYPROJECT["project"]["scripts"]
    assert all(target.startswith("s3rl_torchrl.") for target in scripts.values())


def test_installation_doc_says_why_each_dependency_is_there():
    # docs/installation.md's table has a row per core dependency and per package of the
    # `report` and `bullet` extras (the ones a user installs for a feature, not for tooling).
    table = (ROOT / "docs" / "installation.md").read_text().split("## Dependencies", 1)[1]
    rows = [line.split("|")[1] for line in table.splitlines() if line.startswith("| ")]
    extras = PYPROJECT["project"]["optional-dependencies"]
    wanted = PYPROJECT["project"]["dependencies"] + extras["report"] + extras["bullet"]
    for requirement in wanted:
        name = re.match(r"[A-Za-z0-9_.-]+", requirement).group(0)
        if name == "matplotlib":  # the figures' extra, listed under Extras
            continue
        assert any(name in row for row in rows), f"no row for {name} in docs/installation.md"


def test_a_checkout_reads_the_top_level_configs():
    assert config_dir() == ROOT / "configs"


def _run(cmd: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    out = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, f"{cmd}\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    return out


@pytest.mark.slow
def test_wheel_in_a_fresh_venv_trains_from_another_directory(tmp_path):
    # Build the wheel from a copy of what setuptools reads (the checkout stays clean).
    source = tmp_path / "source"
    for name in ("s3rl_torchrl", "configs"):
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    wheels = tmp_path / "wheels"
    clean_env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(wheels), str(source)],
        cwd=tmp_path, env=clean_env,
    )
    (wheel,) = wheels.glob("s3rl_torchrl-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top_level = {name.split("/")[0] for name in names if not name.startswith("s3rl_torchrl-")}
    assert top_level == {"s3rl_torchrl"}  # no generic top-level `recipes` package
    yamls = sorted(p.relative_to(ROOT / "configs").as_posix() for p in config_dir().rglob("*.yaml"))
    assert sorted(n.removeprefix("s3rl_torchrl/configs/") for n in names
                  if n.endswith(".yaml")) == yamls
    # Data files inside the package (the Circle robots' MJCF, the paper's numbers) ship too.
    data_files = {
        p.relative_to(ROOT).as_posix()
        for p in (ROOT / "s3rl_torchrl").rglob("*")
        if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts
    }
    assert data_files and data_files <= set(names), data_files - set(names)

    # A fresh venv with the wheel installed; the heavy dependencies (torch, torchrl, MuJoCo...)
    # come from this interpreter's site-packages through a .pth line, after the venv's own
    # site-packages, so the package and its configs are the wheel's.
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=False)
    python = env_dir / "bin" / "python"
    purelib = Path(_run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()"
                         "['purelib'])"], cwd=tmp_path, env=clean_env).stdout.strip())
    (purelib / "_shared_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--ignore-installed", str(wheel)],
         cwd=tmp_path, env=clean_env)

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    located = _run(
        [str(python), "-c", "import s3rl_torchrl.recipes as r; print(r.__file__); "
         "print(r.config_dir())"],
        cwd=elsewhere, env=clean_env,
    ).stdout.split()
    assert all(Path(p).is_relative_to(env_dir) for p in located), located

    out = _run([str(env_dir / "bin" / "s3rl-train"), "experiment=tiny"], cwd=elsewhere,
               env=clean_env)
    assert "| gradient steps |" in out.stdout
    (run_dir,) = (elsewhere / "outputs").glob("s3rl/*/seed10/*")
    assert (run_dir / "checkpoints" / "latest" / "state.pt").is_file()
    assert [json.loads((run_dir / "config.json").read_text())["collector"]["total_frames"]] == [600]
    out = _run([str(env_dir / "bin" / "s3rl-eval"), f"checkpoint={run_dir}", "episodes=1",
                "max_steps=10", f"hydra.run.dir={tmp_path / 'eval'}"], cwd=elsewhere, env=clean_env)
    assert json.loads((tmp_path / "eval" / "eval.json").read_text())["length_mean"] == 10.0


def test_test_modules_have_unique_names():
    # tests/ has no __init__.py (pytest's default rootdir import): two test files of one name in
    # different folders fail the whole run at collection, "import file mismatch".
    names: dict[str, list[str]] = {}
    for path in sorted((ROOT / "tests").rglob("test_*.py")):
        names.setdefault(path.name, []).append(str(path.relative_to(ROOT)))
    clashes = {name: paths for name, paths in names.items() if len(paths) > 1}
    assert not clashes, f"test modules sharing a name: {clashes}"
