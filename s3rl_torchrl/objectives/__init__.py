"""TorchRL loss modules and Lagrangian controllers."""

from s3rl_torchrl.objectives.ddpg_lag import (  # noqa: F401
    DDPGLagLoss,
    DDPGLagOptimizers,
    ddpg_lag_update,
    make_ddpg_lag_optimizers,
)
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
from s3rl_torchrl.objectives.nstep import (  # noqa: F401
    NStepTransform,
    make_nstep_transform,
    nstep_transition,
)
from s3rl_torchrl.objectives.ppo_lag import (  # noqa: F401
    PPOLagLoss,
    PPOLagOptimizers,
    compute_ppo_advantages,
    make_ppo_lag_optimizers,
    ppo_lag_update,
)
from s3rl_torchrl.objectives.sac_lag import (  # noqa: F401
    SACLagLoss,
    SACLagOptimizers,
    make_sac_lag_optimizers,
    sac_lag_update,
)
from s3rl_torchrl.objectives.stacked import StackedSACLag  # noqa: F401
from s3rl_torchrl.objectives.target_update import ForeachSoftUpdate  # noqa: F401
