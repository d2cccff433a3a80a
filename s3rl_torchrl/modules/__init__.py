"""Network builders: the S3RL actor (policy encoder + Gaussian head), the deterministic DDPG
actor (same encoder), the critics, and ``BatchedMLP`` (many critics in one chain of batched
matmuls). Nothing here imports from the layers above (objectives, trainer)."""

from s3rl_torchrl.modules.activation import ReLU, relu  # noqa: F401
from s3rl_torchrl.modules.actor import (  # noqa: F401
    DeterministicHead,
    GaussianHead,
    PolicyEncoder,
    build_ddpg_exploration,
    build_deterministic_actor,
    build_s3rl_actor,
    get_policy_encoder,
)
from s3rl_torchrl.modules.batched_mlp import BatchedMLP  # noqa: F401
from s3rl_torchrl.modules.critics import (  # noqa: F401
    build_cost_qvalue_network,
    build_qvalue_network,
    build_value_network,
)
