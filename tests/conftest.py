"""Test-session settings shared by every area."""

from __future__ import annotations

import os

import torch

# Under pytest-xdist (make test: -n 2) each worker keeps to one intra-op thread: two workers
# with two threads each on two cores stall one another (docs/benchmarks.md, threads).
if os.environ.get("PYTEST_XDIST_WORKER"):
    torch.set_num_threads(1)
