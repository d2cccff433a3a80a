"""Hooks: what a run does at fixed points of the trainer besides training, switched on by its
config (``TrainConfig.diagnostics``, the contrastive label), torchrl-style: each hook registers
its methods at the trainer's points (``base.HOOK_POINTS``) and, when it has state, itself as a
module whose state the checkpoint keeps.

- ``labels.GradedLabels``: a graded safety label stored with every step (the contrasted graded
  label, or the cost-to-go the graded probe reads), and old checkpoints' buffers without it;
- ``probes.LinearProbes``: the linear probes of the policy encoder at each epoch's end
  (``probe/*``);
- ``critics.CriticDiagnostics``: the SAC family's critics against recent returns and the actor's
  gradient per loss term (``critic/*``, ``grad/*``);
- ``video.EvalVideo``: a video of one evaluation episode, unsafe steps marked, through the
  run's logger every ``eval.video_interval`` epochs;
- ``policy_average.PolicyAverage``: moving averages of the actor's weights, evaluated beside it
  at every epoch's end and after training (``eval.ema_horizons``).
"""

from s3rl_torchrl.hooks.base import HOOK_POINTS, HookHost, TrainerHook  # noqa: F401
from s3rl_torchrl.hooks.critics import CriticDiagnostics  # noqa: F401
from s3rl_torchrl.hooks.labels import GradedLabels, probed_label  # noqa: F401
from s3rl_torchrl.hooks.policy_average import PolicyAverage  # noqa: F401
from s3rl_torchrl.hooks.probes import LinearProbes  # noqa: F401
from s3rl_torchrl.hooks.video import EvalVideo  # noqa: F401
