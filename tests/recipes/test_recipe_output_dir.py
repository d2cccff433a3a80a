"""What the recipes leave in Hydra's output directory: nothing for a rejected command (only
what Hydra wrote for it is removed), and the console's lines in the job's log."""

from __future__ import annotations

import io
import logging
import os
import sys

import pytest

from s3rl_torchrl.recipes import STARTED, HydraOutput, console_to_log

HYDRA_FILES = ("config.yaml", "hydra.yaml", "overrides.yaml")


def hydra_run_dir(cwd, *parts, log="train.log"):
    """What Hydra makes for a job before its task function runs: the directory (and its
    parents), .hydra/ with three files and an empty job log."""
    run_dir = cwd.joinpath(*parts)
    (run_dir / ".hydra").mkdir(parents=True)
    for name in HYDRA_FILES:
        (run_dir / ".hydra" / name).write_text("x: 1\n")
    (run_dir / log).touch()
    return HydraOutput(run_dir, ".hydra", {run_dir / log: True}, cwd)


def tree(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def test_a_fresh_run_dir_and_the_parents_it_left_empty_are_removed(tmp_path):
    (tmp_path / "outputs" / "s3rl" / "other_run").mkdir(parents=True)
    output = hydra_run_dir(tmp_path, "outputs", "s3rl", "TaskA", "seed10", "2026-01-01_00-00-00")
    assert output.remove_if_untouched()
    # TaskA/seed10/<time> went; outputs/s3rl holds another run's directory, so it stays.
    assert tree(tmp_path) == ["outputs", "outputs/s3rl", "outputs/s3rl/other_run"]


def test_the_working_directory_itself_is_never_removed(tmp_path):
    output = hydra_run_dir(tmp_path, "outputs", "t")
    assert output.remove_if_untouched()
    assert tree(tmp_path) == [] and tmp_path.is_dir()
    cwd_as_run_dir = hydra_run_dir(tmp_path / "here")
    cwd_as_run_dir.cwd = cwd_as_run_dir.dir
    assert not cwd_as_run_dir.remove_if_untouched()


@pytest.mark.parametrize(
    "extra",
    ["user_file", "metrics", "hydra_extra", "old_hydra_file", "old_log", "log_with_content"],
)
def test_a_directory_holding_anything_else_is_kept_intact(tmp_path, extra):
    output = hydra_run_dir(tmp_path, "outputs", "run")
    d = output.dir
    if extra == "user_file":
        (d / "notes.txt").write_text("mine")
    elif extra == "metrics":  # an existing run passed as hydra.run.dir
        (d / "metrics.csv").write_text("frames\n")
    elif extra == "hydra_extra":
        (d / ".hydra" / "mine.yaml").write_text("y: 2\n")
    elif extra == "old_hydra_file":  # not written by this invocation
        old = STARTED - 3600
        os.utime(d / ".hydra" / "config.yaml", (old, old))
    elif extra == "old_log":  # the job log existed before (HydraOutput.current says so)
        output.log_files = {d / "train.log": False}
    elif extra == "log_with_content":
        output.log_files = {d / "train.log": False}
        (d / "train.log").write_text("an earlier run's log\n")
    before = {p: p.read_bytes() for p in d.rglob("*") if p.is_file()}
    assert not output.untouched()
    assert not output.remove_if_untouched()
    assert {p: p.read_bytes() for p in d.rglob("*") if p.is_file()} == before


def test_the_job_log_handler_is_closed_before_its_file_goes(tmp_path):
    output = hydra_run_dir(tmp_path, "run")
    root = logging.getLogger()
    handler = logging.FileHandler(output.dir / "train.log")
    root.addHandler(handler)
    try:
        assert output.remove_if_untouched()
        assert handler not in root.handlers
        logging.getLogger("s3rl_test").warning("after the removal")
        assert not (tmp_path / "run").exists()
    finally:
        root.removeHandler(handler)
        handler.close()


def test_console_lines_go_to_the_job_log_only(tmp_path, monkeypatch):
    root = logging.getLogger()
    file_handler = logging.FileHandler(tmp_path / "train.log")
    file_handler.setFormatter(logging.Formatter("[%(levelname)s] - %(message)s"))
    console = io.StringIO()
    console_handler = logging.StreamHandler(console)
    stdout = io.StringIO()
    monkeypatch.setattr(sys, "stdout", stdout)
    root.addHandler(file_handler)
    root.addHandler(console_handler)
    try:
        with console_to_log("s3rl_test.console") as log:
            print("\nFinal evaluation\n\n| run | reward |\n|---|---:|")
            print("| s3rl | 1.00 |", end="")
            print(" <- same line")
            sys.stdout.write("no newline at the end")
            log.error("s3rl-train: an error")
        assert sys.stdout is stdout  # restored
        print("after the block")
    finally:
        root.removeHandler(file_handler)
        root.removeHandler(console_handler)
        file_handler.close()
    # The console shows exactly what was printed; the log has each non-empty line once.
    assert stdout.getvalue() == (
        "\nFinal evaluation\n\n| run | reward |\n|---|---:|\n| s3rl | 1.00 | <- same line\n"
        "no newline at the endafter the block\n"
    )
    assert (tmp_path / "train.log").read_text().splitlines() == [
        "[INFO] - Final evaluation",
        "[INFO] - | run | reward |",
        "[INFO] - |---|---:|",
        "[INFO] - | s3rl | 1.00 | <- same line",
        "[ERROR] - s3rl-train: an error",
        "[INFO] - no newline at the end",
    ]
    assert console.getvalue() == ""  # nothing twice on the console through logging
