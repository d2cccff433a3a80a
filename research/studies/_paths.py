"""Imported first by every study: puts the repository's ``benchmarks/`` on ``sys.path``, for
``_report`` and the standing benchmarks' scripts a study builds on (``multiseed_throughput``,
``loss_step``). The studies live in ``research/studies/``, outside the package and the standing
benchmarks (research/README.md)."""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BENCHMARKS = REPO / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.insert(0, str(BENCHMARKS))
