"""Network builders: the S3RL actor (policy encoder + Gaussian head), the deterministic DDPG
actor (same encoder), the critics, and the activations a config names (``ACTIVATIONS``).
Nothing here imports from the layers above (objectives, algorithms, trainer)."""

from s3rl_torchrl.modules.activation import ACTIVATIONS, ReLU, relu  # noqa: F401
from s3rl_torchrl.modules.actor import (  # noqa: F401
    DeterministicHead,
    GaussianHead,
    PolicyEncoder,
    build_ddpg_exploration,
    build_deterministic_actor,
    build_s3rl_actor,
    get_policy_encoder,
)
from s3rl_torchrl.modules.critics import (  # noqa: F401
    build_cost_qvalue_network,
    build_qvalue_network,
    build_value_network,
)
