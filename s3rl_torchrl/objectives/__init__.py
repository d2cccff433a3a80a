"""TorchRL losses and the Lagrangian controllers: what an algorithm minimises and how its
multipliers move. The gradient steps that use them are in ``s3rl_torchrl.algorithms``."""

from s3rl_torchrl.objectives.ddpg_lag import DDPGLagLoss  # noqa: F401
from s3rl_torchrl.objectives.graded_infonce import (  # noqa: F401
    GRADED_POSITIVES,
    GradedInfoNCELoss,
    graded_infonce_loss,
)
from s3rl_torchrl.objectives.infonce import (  # noqa: F401
    SafetyInfoNCELoss,
    infonce_logits,
    infonce_loss,
)
from s3rl_torchrl.objectives.lagrangian import (  # noqa: F401
    LAGRANGIAN_CADENCES,
    EpisodeCostWindow,
    LagrangianController,
    LagrangianUpdater,
    LearnedLagrangian,
    PIDLagrangian,
)
from s3rl_torchrl.objectives.ppo_lag import PPOLagLoss  # noqa: F401
from s3rl_torchrl.objectives.sac_lag import SACLagLoss  # noqa: F401
from s3rl_torchrl.objectives.target_update import ForeachSoftUpdate  # noqa: F401
