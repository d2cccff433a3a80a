"""Imported first by every study: puts ``benchmarks/`` on ``sys.path``, for ``_report`` and the
standing benchmarks' scripts a study builds on (``multiseed_throughput``, ``loss_step``)."""

from __future__ import annotations

import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1]
if str(BENCHMARKS) not in sys.path:
    sys.path.insert(0, str(BENCHMARKS))
