"""Diagnostics both the trainer (every epoch) and the results toolkit (``s3rl-report``) compute:
the linear probe of the policy encoder (does the embedding separate safe from unsafe states?).

It sits below :mod:`s3rl_torchrl.trainer` and :mod:`s3rl_torchrl.report` and imports neither
(docs/architecture.md).
"""

from s3rl_torchrl.diagnostics.probe import (
    GradedProbeResult,
    ProbeResult,
    graded_probe,
    linear_probe,
    replay_graded_probe,
    replay_probe,
)

__all__ = [
    "GradedProbeResult",
    "ProbeResult",
    "graded_probe",
    "linear_probe",
    "replay_graded_probe",
    "replay_probe",
]
