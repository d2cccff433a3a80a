"""The algorithm families, one module each: SAC (``sac.py``: S3RL, SAC-Lag, SAC), DDPG
(``ddpg.py``: DDPG-Lag, DDPG) and PPO (``ppo.py``: PPO-Lag, PPO, on-policy).

Each owns its typed config (a subclass of ``config.AlgoConfig`` with its own fields only), its
update schedule (``schedule.py``), its agent builder and its gradient step with its optimisers;
``registry.ALGORITHMS`` maps an algorithm name to its family and defaults. What every family
takes alike lives beside them: the agent and its Lagrangian (``agent.py``), S3RL's contrastive
phase (``contrastive.py``). ``stacked.py`` is the SAC family's step for K seeds at once.
"""

from s3rl_torchrl.algorithms.agent import (  # noqa: F401
    Agent,
    Family,
    Networks,
    build_agent,
    build_lagrangian,
)
from s3rl_torchrl.algorithms.config import (  # noqa: F401
    AlgoConfig,
    ConfigError,
    ContrastiveConfig,
    OffPolicyConfig,
    PIDConfig,
)
from s3rl_torchrl.algorithms.contrastive import ContrastivePhase  # noqa: F401
from s3rl_torchrl.algorithms.ddpg import (  # noqa: F401
    DDPG,
    DDPGConfig,
    ddpg_lag_update,
    make_ddpg_lag_optimizers,
)
from s3rl_torchrl.algorithms.ppo import (  # noqa: F401
    PPO,
    PPOConfig,
    compute_ppo_advantages,
    make_ppo_lag_optimizers,
    ppo_lag_update,
)
from s3rl_torchrl.algorithms.registry import ALGORITHMS, FAMILIES, Algorithm, family_of  # noqa: F401
from s3rl_torchrl.algorithms.sac import (  # noqa: F401
    SAC,
    SACConfig,
    SACLagStep,
    joint_update,
    make_sac_lag_optimizers,
    sac_lag_update,
)
from s3rl_torchrl.algorithms.schedule import (  # noqa: F401
    OffPolicySchedule,
    OnPolicySchedule,
    UpdateSchedule,
)
from s3rl_torchrl.algorithms.stacked import StackedSACLag, draw_noise  # noqa: F401
