"""The S3RL actor: policy encoder (embedding z) -> Gaussian head -> tanh -> action bounds.

Layout as in FSRL's SAC-Lagrangian actor (tianshou ``Net`` + ``ActorProb`` with
``conditioned_sigma``): an MLP trunk whose last hidden activation is the embedding ``z`` the
contrastive loss shapes, then two linear maps from ``z`` to the Gaussian mean and log-std
(clamped), a ``TanhNormal`` rescaled to the action bounds. Orthogonal weights, zero biases.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict.nn import TensorDictModule, TensorDictSequential
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded, TensorSpec
from torchrl.envs.utils import ExplorationType
from torchrl.modules import AdditiveGaussianModule, ProbabilisticActor, TanhNormal

from s3rl_torchrl.modules.activation import ReLU
from s3rl_torchrl.modules.critics import init_orthogonal_

__all__ = [
    "DeterministicHead",
    "GaussianHead",
    "PolicyEncoder",
    "build_ddpg_exploration",
    "build_deterministic_actor",
    "build_s3rl_actor",
    "get_policy_encoder",
]


class PolicyEncoder(TensorDictModule):
    """The actor's trunk as a TensorDictModule ``observation -> embedding``.

    A distinct class so that :func:`get_policy_encoder` finds it inside any actor (or a copy of
    one) without relying on module paths.
    """


class GaussianHead(nn.Module):
    """``z -> (loc, scale)`` with a state-conditioned std.

    ``scale = exp(clamp(W_s z + b_s, *log_std_bounds))``; ``loc = W_m z + b_m``, passed through
    ``tanh`` unless ``unbounded`` (tianshou's ``ActorProb(unbounded=False)`` bound with
    ``max_action = 1``; the paper's Table 3 lists ``unbounded = False``). ``loc`` lives in the
    pre-tanh space of the ``TanhNormal`` that follows.
    """

    def __init__(
        self,
        in_features: int,
        action_dim: int,
        log_std_bounds: tuple[float, float] = (-20.0, 2.0),
        *,
        unbounded: bool = False,
    ):
        super().__init__()
        low, high = (float(b) for b in log_std_bounds)
        if not low < high:
            raise ValueError(
                f"log_std_bounds must be (low, high) with low < high, got {log_std_bounds}."
            )
        self.mu = nn.Linear(in_features, action_dim)
        self.log_std = nn.Linear(in_features, action_dim)
        self.log_std_bounds = (low, high)
        self.unbounded = bool(unbounded)

    def forward(self, embedding: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        loc = self.mu(embedding)
        if not self.unbounded:
            loc = torch.tanh(loc)
        scale = self.log_std(embedding).clamp(*self.log_std_bounds).exp()
        return loc, scale


class DeterministicHead(nn.Module):
    """``z -> low + (tanh(W z + b) + 1) (high - low) / 2``: a deterministic action in bounds.

    tianshou's ``Actor`` (FSRL's DDPG-Lag actor): a linear map, ``tanh``, then the policy's
    action scaling from ``[-1, 1]`` to ``[low, high]``.
    """

    def __init__(self, in_features: int, low: torch.Tensor, high: torch.Tensor):
        super().__init__()
        self.linear = nn.Linear(in_features, low.shape[-1])
        self.register_buffer("loc", (high + low) / 2)
        self.register_buffer("half_range", (high - low) / 2)

    def forward(self, embedding: torch.Tensor) -> torch.Tensor:
        return self.loc + self.half_range * torch.tanh(self.linear(embedding))


def _unbatched_action_spec(action_spec: TensorSpec, caller: str = "build_s3rl_actor") -> Bounded:
    """The per-env action spec: a batched env's spec repeats it along the leading dims."""
    if not isinstance(action_spec, Bounded):
        raise TypeError(
            f"{caller}: action_spec must be a bounded continuous spec "
            f"(torchrl.data.Bounded, e.g. env.action_spec), got {type(action_spec).__name__}."
        )
    if action_spec.ndim == 0:
        raise ValueError(f"{caller}: action_spec must have an action dimension.")
    single = action_spec[(0,) * (action_spec.ndim - 1)] if action_spec.ndim > 1 else action_spec
    low, high = single.space.low, single.space.high
    batched_low = action_spec.space.low.reshape(-1, low.shape[-1])
    batched_high = action_spec.space.high.reshape(-1, high.shape[-1])
    if not (
        torch.equal(batched_low, low.expand_as(batched_low))
        and torch.equal(batched_high, high.expand_as(batched_high))
    ):
        raise ValueError(
            f"{caller}: the batched action_spec has different bounds per env; pass the "
            "spec of one env."
        )
    if not torch.all(high > low):
        raise ValueError(
            f"{caller}: action_spec needs high > low everywhere, got low={low.tolist()}, "
            f"high={high.tolist()}."
        )
    return single


def build_s3rl_actor(
    observation_dim: int,
    action_spec: TensorSpec,
    hidden: Sequence[int] = (128, 128),
    log_std_bounds: tuple[float, float] = (-20.0, 2.0),
    activation: type[nn.Module] = ReLU,
    *,
    unbounded: bool = False,
    observation_key: NestedKey = "observation",
    embedding_key: NestedKey = "embedding",
) -> ProbabilisticActor:
    """Build the S3RL policy as a TorchRL :class:`~torchrl.modules.ProbabilisticActor`.

    ``observation -> [encoder MLP, hidden sizes `hidden`, activation after every layer] ->
    embedding -> GaussianHead -> (loc, scale) -> TanhNormal(low, high) -> action``. The actor
    writes ``"action"`` and its log-probability (``actor.log_prob_keys[0]``), samples by default
    (``ExplorationType.RANDOM``; wrap evaluation in ``set_exploration_type(DETERMINISTIC)`` for
    ``tanh(loc)`` rescaled), and plugs into :class:`torchrl.objectives.SACLoss` as is.

    Args:
        observation_dim: size of the flat observation.
        action_spec: the env's bounded action spec (``env.action_spec``; a batched env's spec
            is reduced to one env's).
        hidden: encoder layer sizes; the last one is the embedding size. Defaults to
            ``(128, 128)`` (paper).
        log_std_bounds: clamp of the log-std. Defaults to ``(-20, 2)`` (FSRL).
        activation: activation class used after every encoder layer. Defaults to
            :class:`~s3rl_torchrl.modules.ReLU` (``nn.ReLU`` that stays fast under ``torch.compile``).

    Keyword Args:
        unbounded: leave the Gaussian mean unsquashed (see :class:`GaussianHead`).
        observation_key, embedding_key: tensordict keys of the encoder.

    Use :func:`get_policy_encoder` to reach the encoder (it shares the actor's parameters).
    """
    encoder, hidden = _policy_encoder(
        observation_dim, hidden, activation, observation_key, embedding_key
    )
    action_spec = _unbatched_action_spec(action_spec)
    low, high = action_spec.space.low, action_spec.space.high
    head = TensorDictModule(
        GaussianHead(hidden[-1], action_spec.shape[-1], log_std_bounds, unbounded=unbounded),
        in_keys=[embedding_key],
        out_keys=["loc", "scale"],
    )
    actor = ProbabilisticActor(
        TensorDictSequential(encoder, head),
        in_keys=["loc", "scale"],
        spec=action_spec,
        distribution_class=TanhNormal,
        distribution_kwargs={"low": low, "high": high, "tanh_loc": False},
        return_log_prob=True,
        default_interaction_type=ExplorationType.RANDOM,
    )
    return init_orthogonal_(actor)  # FSRL's initialisation, as the critics


def _policy_encoder(
    observation_dim: int,
    hidden: Sequence[int],
    activation: type[nn.Module],
    observation_key: NestedKey,
    embedding_key: NestedKey,
) -> tuple[PolicyEncoder, tuple[int, ...]]:
    observation_dim = int(observation_dim)
    hidden = tuple(int(h) for h in hidden)
    if observation_dim < 1:
        raise ValueError(f"observation_dim must be >= 1, got {observation_dim}.")
    if not hidden or min(hidden) < 1:
        raise ValueError(
            f"hidden must be a non-empty sequence of positive layer sizes (the last is the "
            f"embedding size), got {hidden}."
        )
    layers: list[nn.Module] = []
    in_features = observation_dim
    for width in hidden:
        layers += [nn.Linear(in_features, width), activation()]
        in_features = width
    encoder = PolicyEncoder(
        nn.Sequential(*layers), in_keys=[observation_key], out_keys=[embedding_key]
    )
    return encoder, hidden


def build_deterministic_actor(
    observation_dim: int,
    action_spec: TensorSpec,
    hidden: Sequence[int] = (128, 128),
    activation: type[nn.Module] = ReLU,
    *,
    observation_key: NestedKey = "observation",
    embedding_key: NestedKey = "embedding",
    action_key: NestedKey = "action",
) -> TensorDictSequential:
    """Build a deterministic policy ``observation -> action`` for DDPG(-Lag).

    ``observation -> PolicyEncoder (MLP, hidden sizes `hidden`, activation after every layer) ->
    embedding -> DeterministicHead -> action in [low, high]``: FSRL's DDPG-Lag actor (tianshou
    ``Net`` + ``Actor``, ``fsrl/agent/ddpg_lag_agent.py``) with the same trunk class as
    :func:`build_s3rl_actor`, so :func:`get_policy_encoder`, ``SafetyInfoNCELoss`` and
    ``ContrastivePhase`` work on it unchanged. Orthogonal weights, zero biases.

    It plugs into :class:`torchrl.objectives.DDPGLoss` and
    :class:`~s3rl_torchrl.objectives.DDPGLagLoss` as is; collect with
    :func:`build_ddpg_exploration` around it.
    """
    action_spec = _unbatched_action_spec(action_spec, "build_deterministic_actor")
    low, high = action_spec.space.low, action_spec.space.high
    encoder, hidden = _policy_encoder(
        observation_dim, hidden, activation, observation_key, embedding_key
    )
    head = TensorDictModule(
        DeterministicHead(hidden[-1], low.float(), high.float()),
        in_keys=[embedding_key],
        out_keys=[action_key],
    )
    actor = TensorDictSequential(encoder, head)
    return init_orthogonal_(actor)  # FSRL's initialisation, as the critics


def build_ddpg_exploration(
    actor: TensorDictModule,
    action_spec: TensorSpec,
    sigma: float = 0.1,
    *,
    action_key: NestedKey = "action",
) -> TensorDictSequential:
    """The collection policy of DDPG: ``actor`` followed by additive Gaussian noise.

    FSRL's default exploration (``GaussianNoise(sigma=0.1)`` in ``fsrl/policy/ddpg_lag.py``)
    adds ``N(0, sigma^2)`` to the action in tianshou's ``[-1, 1]`` action scale; here that is
    torchrl's :class:`~torchrl.modules.AdditiveGaussianModule` with a constant ``sigma`` and a
    per-dimension ``std`` of half the action range, followed by clipping to the bounds (tianshou's
    ``action_bound_method="clip"``). The noise is added only under
    ``ExplorationType.RANDOM`` (the collector's default); evaluation with
    ``set_exploration_type(DETERMINISTIC)`` gives the actor's own action. The actor's parameters
    are shared, not copied.
    """
    sigma = float(sigma)
    if not sigma >= 0:
        raise ValueError(f"sigma must be >= 0, got {sigma!r}.")
    single = _unbatched_action_spec(action_spec, "build_ddpg_exploration")
    noise = AdditiveGaussianModule(
        single,
        sigma_init=sigma,
        sigma_end=sigma,
        annealing_num_steps=1,
        action_key=action_key,
    )
    noise.std = ((single.space.high - single.space.low) / 2).float()
    return TensorDictSequential(actor, noise)


def get_policy_encoder(actor: nn.Module) -> PolicyEncoder:
    """The encoder (``observation -> embedding``) inside an actor from :func:`build_s3rl_actor`
    or :func:`build_deterministic_actor`.

    It is the actor's own submodule: training it trains the actor's trunk.
    """
    encoders = [m for m in actor.modules() if isinstance(m, PolicyEncoder)]
    if len(encoders) != 1:
        raise ValueError(
            f"get_policy_encoder: expected exactly one PolicyEncoder inside the actor, found "
            f"{len(encoders)}; build the actor with build_s3rl_actor (or wrap your trunk in "
            "s3rl_torchrl.modules.PolicyEncoder)."
        )
    return encoders[0]
