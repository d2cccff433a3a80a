"""docs/video.md's evaluation-speed numbers are those of the committed rounds
(research/results/eval_speed_video.json), recomputed here from the rounds themselves."""

from __future__ import annotations

import json
import re
import statistics
from pathlib import Path

from scipy.stats import mannwhitneyu

ROOT = Path(__file__).resolve().parents[2]
RESULT = ROOT / "research" / "results" / "eval_speed_video.json"
FAMILIES = ("velocity", "circle", "goal", "bullet")  # the order docs/video.md names them in


def _text() -> str:
    return re.sub(r"\s+", " ", (ROOT / "docs" / "video.md").read_text())


def _values(rows: dict, label: str, key: str) -> list[float]:
    return [r[key] for family in FAMILIES for r in rows[f"{family}/{label}"]]


def test_per_step_medians_and_import_are_the_rounds():
    rows = json.loads(RESULT.read_text())["rows"]
    text = _text()

    def medians(label: str) -> str:
        return " / ".join(
            f"{statistics.median(r['eval_cpu_ms_per_step'] for r in rows[f'{f}/{label}']):.2f}"
            for f in FAMILIES
        )

    assert f"BallRun: {medians('after')}, against {medians('before')} before headless video" in text
    after, before = (statistics.median(_values(rows, x, "import_cpu_s")) for x in ("after", "before"))
    assert f"`import s3rl_torchrl`: {after:.2f} against {before:.2f} s of CPU" in text


def test_the_stated_tests_are_the_rounds():
    rows = json.loads(RESULT.read_text())["rows"]
    per_family = [
        mannwhitneyu(
            [r["eval_cpu_ms_per_step"] for r in rows[f"{f}/after"]],
            [r["eval_cpu_ms_per_step"] for r in rows[f"{f}/before"]],
        ).pvalue
        for f in FAMILIES
    ]
    imports = mannwhitneyu(
        _values(rows, "after", "import_cpu_s"), _values(rows, "before", "import_cpu_s")
    ).pvalue
    text = _text()
    assert f"Mann-Whitney p {min(per_family):.2f}-{max(per_family):.2f}; import {imports:.2f}" in text
    assert all(len(rows[f"{f}/{x}"]) == 5 for f in FAMILIES for x in ("before", "after"))
    assert "Medians of 5 interleaved rounds" in text
