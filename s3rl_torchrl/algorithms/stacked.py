"""K independent SAC-Lag agents updated as one batched computation (several seeds, one process).

:class:`StackedSACLag` takes ``K`` :class:`~s3rl_torchrl.objectives.SACLagLoss` of one
architecture (one per seed) and stacks each of their per-agent tensors (actor, critics, target
critics, log alpha, lambda: ``PER_AGENT``) into one tensor with a leading seed dimension
``[K, ...]``. Each agent's own tensors then become views of its
slice, so the agents stay ordinary single-seed objects for everything else (collecting with
their actor, the contrastive phase on their encoder, evaluation, ``state_dict``), while a
gradient step runs the loss once under ``torch.vmap`` over the seed dimension (a template
copy of the loss reads the agent's tensors through properties):

* the group's objective is the SUM of the agents' losses, so agent ``k``'s gradient is exactly
  its single-run gradient (nothing mixes across the seed dimension: every op is vmapped);
* one Adam per parameter group over the stacked tensors IS ``K`` independent Adams (Adam is
  elementwise; every agent steps together, so the shared step count is each agent's);
* the target update is one elementwise lerp over the stacked tensors;
* alpha and the Lagrangian multipliers are per agent (``[K]`` and ``[K, m]`` slices).

Randomness: the loss draws two standard-normal tensors per step (the next action of the
targets, then the reparameterised action of the actor loss). Under ``vmap`` those draws would
come from one shared stream, so the caller draws them outside, one agent at a time from that
agent's own generator state, and passes them in (``noise``); inside, the draws of
``torch.distributions.Normal.rsample`` are replaced by them in order. Agent ``k`` therefore
consumes its random stream exactly as a single-seed run does.
"""

from __future__ import annotations

import contextlib
import copy
from collections.abc import Callable, Iterator, Sequence

import torch
import torch.distributions.normal as _normal
from tensordict import TensorDict, TensorDictBase
from torch import Tensor

from s3rl_torchrl.algorithms.sac import joint_update, sac_parameter_groups
from s3rl_torchrl.objectives import SACLagLoss

__all__ = ["StackedSACLag"]

# The loss draws the next action of the critic targets, then the actor's action.
NOISE_DRAWS = 2


@contextlib.contextmanager
def _normal_noise(noise: Sequence[Tensor]) -> Iterator[None]:
    """Within the block, ``Normal.rsample`` takes its standard-normal draws from ``noise``."""
    remaining = list(noise)
    original = _normal._standard_normal

    def draw(shape, dtype, device):
        if not remaining:
            raise RuntimeError("the loss drew more normal samples than were provided")
        eps = remaining.pop(0)
        if tuple(eps.shape) != tuple(shape):
            raise RuntimeError(f"noise of shape {tuple(eps.shape)} for a draw of shape {shape}")
        return eps.to(dtype)

    _normal._standard_normal = draw
    try:
        yield
    finally:
        _normal._standard_normal = original
    if remaining:
        raise RuntimeError(f"{len(remaining)} noise tensors were not used by the loss")


def _as_tuple(key) -> tuple:
    return key if isinstance(key, tuple) else (key,)


def draw_noise(batch_size: int, action_dim: int, dtype=torch.float32) -> Tensor:
    """One agent's draws for one step ``[NOISE_DRAWS, B, A]``, from the global generator, in
    the order and manner of ``Normal.rsample`` (``torch.empty(...).normal_()``)."""
    return torch.stack(
        [torch.empty(batch_size, action_dim, dtype=dtype).normal_() for _ in range(NOISE_DRAWS)]
    )


# The tensors that differ between agents; the rest (discount, target entropy) comes from the
# configuration and must be equal across agents.
PER_AGENT = (
    "actor_network_params",
    "qvalue_network_params",
    "target_qvalue_network_params",
    "cost_qvalue_network_params",
    "target_cost_qvalue_network_params",
    "log_alpha",
    "alpha_init",
    "lagrangian",
)


class _Current:
    """The tensors of the agent being computed (batched ones inside ``vmap``)."""

    params: TensorDictBase | None = None


def _template_loss(loss: SACLagLoss) -> SACLagLoss:
    """A copy of ``loss`` that reads its per-agent tensors from ``loss._current.params``.

    Plain attribute reads, nothing swapped into modules: ``TensorDict.to_module`` on a whole
    loss breaks ``torch.compile``'s graph inside ``vmap`` (then the whole step runs eager).
    A parameter tensordict read inside the ``vmap`` over agents gets back the batch size it has
    in the loss (``[N]``, the critics of a signal): the loss maps its critics over it.
    """
    batch_sizes = {
        name: getattr(loss, name).batch_size
        for name in PER_AGENT
        if isinstance(getattr(loss, name, None), TensorDictBase)
    }

    def params(self, name: str, detach: bool = False):
        value = self._current.params.get(name)
        if name in batch_sizes:
            value = value.detach() if detach else value
            value.batch_size = batch_sizes[name]
        elif detach:
            value = value.detach()
        return value

    def read(name):
        return property(lambda self: params(self, name))

    def detached(name):
        return property(lambda self: params(self, name, detach=True))

    namespace = {name: read(name) for name in PER_AGENT}
    # SACLoss caches these as attributes; here they are views of this call's tensors.
    namespace["_cached_detached_qvalue_params"] = detached("qvalue_network_params")
    namespace["_cached_detached_cost_qvalue_params"] = detached("cost_qvalue_network_params")
    # Clears the weakrefs of the loss's own parameter containers before returning a compiled
    # result; here there are none (and it reads `.data` of the actor's, refused under vmap).
    namespace["_clear_weakrefs"] = lambda self, *tds: None
    template = copy.deepcopy(loss)
    template.__class__ = type(f"_Stacked{type(loss).__name__}", (type(loss),), namespace)
    template.__dict__["_current"] = _Current()
    return template


class StackedSACLag:
    """``K`` ``SACLagLoss`` of one architecture, stacked and updated together.

    Args:
        losses: the agents' losses (built the same way, e.g. by ``build_agent`` per seed).
        actor_lr, critic_lr, alpha_lr: Adam learning rates (as ``make_sac_lag_optimizers``).
        tau: target update rate (as ``ForeachSoftUpdate``).
        compile_fn: applied to the vmapped loss function, e.g. ``torch.compile`` (the trainer
            passes its ``compile_loss``); ``None``: eager.

    After construction, every tensor of ``losses[k]`` is a view of slice ``k`` of
    :attr:`params`; :meth:`update` changes them in place.
    """

    def __init__(
        self,
        losses: Sequence[SACLagLoss],
        actor_lr: float,
        critic_lr: float,
        alpha_lr: float,
        tau: float,
        *,
        compile_fn: Callable | None = None,
    ) -> None:
        if not losses:
            raise ValueError("StackedSACLag needs at least one loss")
        if losses[0].reduction == "none":
            raise ValueError("StackedSACLag needs scalar losses (reduction='mean' or 'sum')")
        self.losses = list(losses)
        self.num_agents = len(losses)
        # The module that computes every agent's loss, reading the agent's tensors from the
        # stacks (PER_AGENT); its own copies of the shared ones (discount, target entropy).
        self._template = _template_loss(losses[0])
        per_agent = [TensorDict.from_module(loss) for loss in losses]
        keys = list(per_agent[0].keys(True, True))
        for k, td in enumerate(per_agent[1:], 1):
            if sorted(map(str, td.keys(True, True))) != sorted(map(str, keys)):
                raise ValueError(f"loss {k} does not have the parameters of loss 0")
            for key in keys:
                name = key[0] if isinstance(key, tuple) else key
                if name not in PER_AGENT and not torch.equal(td.get(key), per_agent[0].get(key)):
                    raise ValueError(f"the losses differ in {key}, which StackedSACLag shares")
        stacked, stack_of = {}, {}
        for key in keys:
            if (key[0] if isinstance(key, tuple) else key) not in PER_AGENT:
                continue
            leaves = [td.get(key) for td in per_agent]
            value = torch.stack([leaf.detach() for leaf in leaves])
            if isinstance(leaves[0], torch.nn.Parameter):
                value = torch.nn.Parameter(value, requires_grad=leaves[0].requires_grad)
            stacked[key], stack_of[id(leaves[0])] = value, value
            for k, leaf in enumerate(leaves):
                # Same tensor object, storage now a slice of the stack: every holder of it (the
                # actor module, the contrastive optimizer, the loss) sees the group's updates.
                leaf.data = value.data[k]
        self.params = TensorDict(stacked, batch_size=[self.num_agents])

        # The single run's parameter groups (sac_parameter_groups), each tensor replaced by its
        # stack: each agent's slice of an optimizer state is then its single-run state.
        self.param_groups = {
            name: [stack_of[id(tensor)] for tensor in tensors]
            for name, tensors in sac_parameter_groups(losses[0]).items()
        }
        rates = {"actor": actor_lr, "critic": critic_lr, "alpha": alpha_lr}
        self.optimizers = {
            name: torch.optim.Adam(params, lr=rates[name], fused=True)
            for name, params in self.param_groups.items()
        }
        targets, sources = [], []
        for name in ("qvalue_network_params", "cost_qvalue_network_params"):
            target = self.params.get("target_" + name, None)
            if target is None:
                continue
            for key, value in target.items(True, True):
                targets.append(value)
                sources.append(self.params.get((name, *_as_tuple(key))))
        self._targets, self._sources, self._tau = targets, sources, tau
        self._loss = torch.vmap(self._one_agent, (0, 0, 0), randomness="error")
        if compile_fn is not None:
            self._loss = compile_fn(self._loss)

    # ------------------------------------------------------------------ one agent, vmapped
    def _one_agent(self, params: TensorDictBase, batch: TensorDictBase, noise: Tensor):
        loss = self._template
        loss._current.params = params
        try:
            with _normal_noise(noise.unbind(0)):
                return loss(batch)
        finally:
            loss._current.params = None

    def loss(self, batches: TensorDictBase, noise: Tensor) -> TensorDictBase:
        """Every agent's ``SACLagLoss.forward`` on its batch: entries ``[K, ...]``.

        ``batches``: ``[K, B]``, agent ``k``'s batch at index ``k``; ``noise``:
        ``[K, NOISE_DRAWS, B, action_dim]`` (:func:`draw_noise` per agent).
        """
        return self._loss(self.params, batches, noise)

    def update(self, batches: TensorDictBase, noise: Tensor) -> TensorDictBase:
        """One joint gradient step of every agent (the paper's Algorithm 3, as the single-seed
        loop's ``update_order="joint"``): one forward, one backward of the SUM of every agent's
        summed losses, every optimiser, the target update. Returns the detached losses."""
        return joint_update(self.loss(batches, noise), self.optimizers.values(), self._lerp_targets)

    @torch.no_grad()
    def _lerp_targets(self) -> None:
        """Every agent's target critics, one elementwise lerp (as ``ForeachSoftUpdate``)."""
        torch._foreach_lerp_(self._targets, self._sources, self._tau)

    # ------------------------------------------------------------------ per-agent state
    def optimizer_state(self, agent: int) -> dict[str, dict]:
        """Agent ``agent``'s slice of the optimiser states, in the format of its single-run
        optimisers (``make_sac_lag_optimizers``' state dicts)."""
        out = {}
        for name, optimizer in self.optimizers.items():
            state = optimizer.state_dict()
            out[name] = {
                "state": {
                    index: {
                        key: value.clone() if key == "step" else value[agent].clone()
                        for key, value in entry.items()
                    }
                    for index, entry in state["state"].items()
                },
                "param_groups": state["param_groups"],
            }
        return out

    def load_optimizer_states(self, states: Sequence[dict[str, dict]]) -> None:
        """Stack per-agent optimiser states (:meth:`optimizer_state`) back into the group's."""
        if len(states) != self.num_agents:
            raise ValueError(f"{len(states)} optimizer states for {self.num_agents} agents")
        for name, optimizer in self.optimizers.items():
            first = states[0][name]
            steps = {float(s[name]["state"].get(0, {}).get("step", 0)) for s in states}
            if len(steps) > 1:
                raise ValueError(f"the agents' {name} optimizers are at different steps")
            merged = {
                index: {
                    key: value
                    if key == "step"
                    else torch.stack([s[name]["state"][index][key] for s in states])
                    for key, value in entry.items()
                }
                for index, entry in first["state"].items()
            }
            optimizer.load_state_dict(
                {"state": merged, "param_groups": optimizer.state_dict()["param_groups"]}
            )
