"""SACLagLoss against torchrl's SACLoss and against hand computations of FSRL's formulas."""

from __future__ import annotations

import copy

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.data import Bounded, LazyTensorStorage, ReplayBuffer
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import SACLoss, SoftUpdate
from torchrl.objectives.sac import compute_rsample_log_prob

from s3rl_torchrl.modules import build_cost_qvalue_network, build_qvalue_network
from s3rl_torchrl.objectives import ForeachSoftUpdate, PIDLagrangian, SACLagLoss
from s3rl_torchrl.transforms import make_nstep_transform
from tests.objectives._gradients import moved

OBS, ACT, HIDDEN, GAMMA, ALPHA = 5, 2, (16, 16), 0.9, 0.005


def make_actor(seed: int = 0) -> ProbabilisticActor:
    torch.manual_seed(seed)
    spec = Bounded(-torch.ones(ACT), torch.ones(ACT), (ACT,))
    net = nn.Sequential(
        MLP(in_features=OBS, out_features=2 * ACT, num_cells=list(HIDDEN)), NormalParamExtractor()
    )
    module = TensorDictModule(net, in_keys=["observation"], out_keys=["loc", "scale"])
    return ProbabilisticActor(
        module, in_keys=["loc", "scale"], spec=spec, distribution_class=TanhNormal
    )


def make_critics(n: int, cost: bool = False, seed: int = 1) -> list[TensorDictModule]:
    torch.manual_seed(seed)
    build = build_cost_qvalue_network if cost else build_qvalue_network
    return [build(OBS, ACT, HIDDEN) for _ in range(n)]


def make_batch(batch: int = 32, num_costs: int = 1, seed: int = 2, steps: bool = True):
    g = torch.Generator().manual_seed(seed)
    terminated = torch.rand(batch, 1, generator=g) < 0.3
    # Cost columns on different scales so that a swapped cost/critic pairing shows.
    cost = torch.rand(batch, num_costs, generator=g) * torch.arange(1, num_costs + 1) ** 2
    data = {
        "observation": torch.randn(batch, OBS, generator=g),
        "action": torch.rand(batch, ACT, generator=g) * 2 - 1,
        "next": {
            "observation": torch.randn(batch, OBS, generator=g),
            "reward": torch.randn(batch, 1, generator=g),
            "cost": cost,
            "terminated": terminated,
            "done": terminated | (torch.rand(batch, 1, generator=g) < 0.2),
        },
    }
    if steps:
        data["steps_to_next_obs"] = torch.randint(1, 3, (batch,), generator=g)
    return TensorDict(data, [batch])


def make_loss(num_costs: int = 1, **kwargs):
    actor = make_actor()
    critics = make_critics(2)
    costs = make_critics(2 * num_costs, cost=True, seed=3) if num_costs else None
    loss = SACLagLoss(actor, critics, costs, num_costs=num_costs, **kwargs)
    loss.make_value_estimator(gamma=GAMMA)
    return loss, actor, critics, costs


def q_values(critics, obs, action) -> torch.Tensor:
    """Each critic module called directly: the reference for the loss's ensemble evaluation."""
    td = TensorDict({"observation": obs, "action": action}, obs.shape[:-1])
    return torch.stack([c(td.clone())[c.out_keys[0]].squeeze(-1) for c in critics])


def sample(actor, obs):
    with set_exploration_type(ExplorationType.RANDOM):
        dist = actor.get_dist(TensorDict({"observation": obs}, obs.shape[:-1]))
        return compute_rsample_log_prob(dist)


def grads(loss, names):
    out = {}
    for name in names:
        params = getattr(loss, name)
        if isinstance(params, nn.Parameter):
            out[name] = params.grad.clone()
            continue
        for key, value in params.flatten_keys().items():
            out[f"{name}.{key}"] = value.grad.clone()
    return out


def run(loss, batch, seed):
    torch.manual_seed(seed)
    out = loss(batch.clone())
    sum(v for k, v in out.items() if k.startswith("loss_")).backward()
    return out


def close(a, b, rtol=1e-5, atol=1e-6):
    torch.testing.assert_close(a, b, rtol=rtol, atol=atol)


# --------------------------------------------------------------------------- SACLoss equivalence
@pytest.mark.parametrize("loss_function", ["l2", "smooth_l1"])
def test_matches_sacloss_without_cost_critics(loss_function):
    actor, critics = make_actor(), make_critics(2)
    sac = SACLoss(actor, critics, loss_function=loss_function, alpha_init=ALPHA)
    lag = SACLagLoss(copy.deepcopy(actor), critics, loss_function=loss_function, alpha_init=ALPHA)
    assert lag.num_costs == 0 and lag.lagrangian.shape == (0,)
    for loss in (sac, lag):
        loss.make_value_estimator(gamma=GAMMA)
    batch = make_batch()
    out_sac, out_lag = run(sac, batch, 3), run(lag, batch, 3)
    for key in ("loss_actor", "loss_qvalue", "loss_alpha", "alpha", "entropy"):
        close(out_lag[key], out_sac[key])
    assert float(out_lag["loss_cost_qvalue"]) == 0.0
    names = ("actor_network_params", "qvalue_network_params", "log_alpha")
    g_sac, g_lag = grads(sac, names), grads(lag, names)
    assert g_sac.keys() == g_lag.keys()
    for key in g_sac:
        close(g_lag[key], g_sac[key], rtol=1e-4, atol=1e-6)


def test_zero_lagrangian_matches_sacloss_and_still_trains_cost_critics():
    actor, critics = make_actor(), make_critics(2)
    sac = SACLoss(actor, critics, loss_function="l2", alpha_init=ALPHA)
    lag = SACLagLoss(copy.deepcopy(actor), critics, make_critics(4, cost=True), num_costs=2)
    for loss in (sac, lag):
        loss.make_value_estimator(gamma=GAMMA)
    batch = make_batch(num_costs=2)
    out_sac, out_lag = run(sac, batch, 4), run(lag, batch, 4)
    for key in ("loss_actor", "loss_qvalue", "loss_alpha", "alpha", "entropy"):
        close(out_lag[key], out_sac[key])
    names = ("actor_network_params", "qvalue_network_params", "log_alpha")
    g_sac, g_lag = grads(sac, names), grads(lag, names)
    for key in g_sac:
        close(g_lag[key], g_sac[key], rtol=1e-4, atol=1e-6)
    assert float(out_lag["loss_cost_qvalue"].detach()) > 0
    cost_grads = grads(lag, ("cost_qvalue_network_params",))
    assert all(bool(g.abs().sum() > 0) for g in cost_grads.values())


# --------------------------------------------------------------------------- targets
# A trajectory of 10 steps with a termination at step 3 and a truncation at step 7, written to a
# replay buffer through the n-step transform in two extends. For each stored step t (hand-made):
# END[t]: the step whose next observation is bootstrapped; BOOT[t]: 0 if the window ends in a
# termination. The transform holds back the last n steps, hence 10 - n stored transitions.
END = {2: [1, 2, 3, 3, 5, 6, 7, 7], 3: [2, 3, 3, 3, 6, 7, 7]}
BOOT = {2: [1, 1, 0, 0, 1, 1, 1, 1], 3: [1, 0, 0, 0, 1, 1, 1]}


def trajectory(T: int = 10) -> TensorDict:
    g = torch.Generator().manual_seed(11)
    terminated = torch.zeros(T, 1, dtype=torch.bool)
    truncated = torch.zeros(T, 1, dtype=torch.bool)
    terminated[3], truncated[7] = True, True
    t = torch.arange(T, dtype=torch.float32)[:, None]
    return TensorDict(
        {
            "observation": torch.randn(T, OBS, generator=g),
            "action": torch.rand(T, ACT, generator=g) * 2 - 1,
            "next": {
                "observation": torch.randn(T, OBS, generator=g),
                "reward": t + 1,
                "cost": (t % 2 == 0).float(),
                "terminated": terminated,
                "truncated": truncated,
                "done": terminated | truncated,
            },
        },
        [T],
    )


@pytest.mark.parametrize("n_steps", [2, 3])
@pytest.mark.parametrize("entropy_in_cost_target", [True, False])
def test_nstep_targets_by_hand(n_steps, entropy_in_cost_target):
    traj = trajectory()
    transform = make_nstep_transform(n_steps, GAMMA)
    rb = ReplayBuffer(storage=LazyTensorStorage(20), transform=transform)
    rb.extend(traj[:6])
    rb.extend(traj[6:])
    batch = rb[:]
    loss, actor, critics, costs = make_loss(1, entropy_in_cost_target=entropy_in_cost_target)
    torch.manual_seed(5)
    target_r, target_c = loss.compute_targets(batch)

    end, boot = torch.tensor(END[n_steps]), torch.tensor(BOOT[n_steps], dtype=torch.float32)
    torch.manual_seed(5)
    a_next, logp = sample(actor, traj["next", "observation"][end])
    v_r = q_values(critics, traj["next", "observation"][end], a_next).min(0)[0] - ALPHA * logp
    v_c = q_values(costs, traj["next", "observation"][end], a_next).min(0)[0]
    if entropy_in_cost_target:
        v_c = v_c - ALPHA * logp
    r, c = traj["next", "reward"].squeeze(-1), traj["next", "cost"].squeeze(-1)
    expected_r, expected_c = [], []
    for t, e in enumerate(END[n_steps]):
        k = e - t
        disc = torch.tensor([GAMMA**j for j in range(k + 1)])
        bootstrap = boot[t] * GAMMA ** (k + 1)
        expected_r.append((disc * r[t : e + 1]).sum() + bootstrap * v_r[t])
        expected_c.append((disc * c[t : e + 1]).sum() + bootstrap * v_c[t])
    close(target_r, torch.stack(expected_r), atol=1e-5)
    close(target_c[:, 0], torch.stack(expected_c), atol=1e-5)


def test_one_step_targets_pair_each_cost_with_its_critics():
    loss, actor, critics, costs = make_loss(2)
    batch = make_batch(num_costs=2, steps=False)
    torch.manual_seed(6)
    target_r, target_c = loss.compute_targets(batch)
    torch.manual_seed(6)
    nxt = batch["next", "observation"]
    a_next, logp = sample(actor, nxt)
    alive = (~batch["next", "terminated"].squeeze(-1)).float()
    q_c = q_values(costs, nxt, a_next)  # [4, B]: cost 0 -> nets 0, 1; cost 1 -> nets 2, 3
    for i in range(2):
        v = torch.minimum(q_c[2 * i], q_c[2 * i + 1]) - ALPHA * logp
        close(target_c[:, i], batch["next", "cost"][:, i] + GAMMA * alive * v, atol=1e-5)
    v_r = q_values(critics, nxt, a_next).min(0)[0] - ALPHA * logp
    close(target_r, batch["next", "reward"].squeeze(-1) + GAMMA * alive * v_r, atol=1e-5)


# --------------------------------------------------------------------------- losses by hand
def test_critic_losses_two_costs_by_hand():
    loss, _, critics, costs = make_loss(2)
    batch = make_batch(num_costs=2)
    torch.manual_seed(9)
    target_r, target_c = loss.compute_targets(batch)
    torch.manual_seed(9)
    loss_qvalue, metadata = loss.qvalue_v2_loss(batch)
    q_r = q_values(critics, batch["observation"], batch["action"])
    q_c = q_values(costs, batch["observation"], batch["action"])
    # FSRL: squared error, mean over the batch, summed over the critics.
    expected_r = sum(((q_r[j] - target_r) ** 2).mean() for j in range(2))
    expected_c = sum(
        ((q_c[2 * i + j] - target_c[:, i]) ** 2).mean() for i in range(2) for j in range(2)
    )
    close(loss_qvalue, expected_r)
    close(metadata["loss_cost_qvalue"], expected_c)
    assert metadata["td_error"].shape == (32,)


@pytest.mark.parametrize("rescaling", [True, False])
def test_actor_loss_two_costs_by_hand(rescaling):
    loss, actor, critics, costs = make_loss(2, rescaling=rescaling)
    loss.lagrangian = [0.3, 1.2]
    batch = make_batch(num_costs=2)
    obs = batch["observation"]

    def expected(a, logp):
        q_c = q_values(costs, obs, a)
        min_c = torch.stack([torch.minimum(q_c[0], q_c[1]), torch.minimum(q_c[2], q_c[3])])
        value = (ALPHA * logp - q_values(critics, obs, a).min(0)[0]).mean()
        value = value + 0.3 * min_c[0].mean() + 1.2 * min_c[1].mean()
        return value / (1 + 1.5) if rescaling else value, min_c.mean(1)

    # The actor loss alone (FSRL order: after the critic step).
    torch.manual_seed(7)
    loss_actor, meta = loss.actor_loss(batch.clone())
    torch.manual_seed(7)
    ref, ref_cost_q = expected(*sample(actor, obs))
    close(loss_actor, ref)
    close(meta["cost_q"], ref_cost_q)
    # Inside the forward, which first samples the next action for the targets.
    torch.manual_seed(8)
    out = loss(batch.clone())
    torch.manual_seed(8)
    sample(actor, batch["next", "observation"])
    ref, ref_cost_q = expected(*sample(actor, obs))
    close(out["loss_actor"], ref)
    close(out["cost_q"], ref_cost_q)
    assert out["lagrangian"].tolist() == pytest.approx([0.3, 1.2])


def test_rescaling_divides_the_whole_actor_loss():
    on, *_ = make_loss(1, rescaling=True)
    off, *_ = make_loss(1, rescaling=False)
    batch = make_batch()
    for loss in (on, off):
        loss.lagrangian = 2.0
    torch.manual_seed(1)
    l_on, _ = on.actor_loss(batch.clone())
    torch.manual_seed(1)
    l_off, _ = off.actor_loss(batch.clone())
    close(l_on * 3.0, l_off)


# --------------------------------------------------------------------------- gradient flow
def test_gradient_isolation():
    loss, *_ = make_loss(2)
    loss.lagrangian = [0.5, 0.7]
    out = loss(make_batch(num_costs=2))
    groups = {
        "actor": list(loss.actor_network_params.values(True, True)),
        "critics": list(loss.qvalue_network_params.values(True, True))
        + list(loss.cost_qvalue_network_params.values(True, True)),
        "alpha": [loss.log_alpha],
    }

    assert moved(out["loss_qvalue"] + out["loss_cost_qvalue"], groups) == {
        "actor": False,
        "critics": True,
        "alpha": False,
    }
    assert moved(out["loss_actor"], groups) == {"actor": True, "critics": False, "alpha": False}
    assert moved(out["loss_alpha"], groups) == {"actor": False, "critics": False, "alpha": True}


def test_critics_of_any_architecture():
    # The critics are evaluated as SACLoss evaluates them (one vmap per kind): cost critics of
    # another size than the reward critics, and critics with dropout, work alike.
    torch.manual_seed(0)
    small_costs = [build_cost_qvalue_network(OBS, ACT, (8,)) for _ in range(2)]
    loss = SACLagLoss(make_actor(), make_critics(2), small_costs, num_costs=1)
    loss.make_value_estimator(gamma=GAMMA)
    batch = make_batch()
    q_r, q_c = loss.critic_values(batch)
    close(q_c[0], q_values(small_costs, batch["observation"], batch["action"]))
    assert torch.isfinite(loss(batch)["loss_cost_qvalue"])
    dropout = [
        ValueOperator(
            MLP(in_features=OBS + ACT, out_features=1, num_cells=[8], dropout=0.1),
            in_keys=["observation", "action"],
        )
        for _ in range(2)
    ]
    unconstrained = SACLagLoss(make_actor(), dropout)
    unconstrained.make_value_estimator(gamma=GAMMA)
    assert torch.isfinite(unconstrained(make_batch())["loss_qvalue"])


# --------------------------------------------------------------------------- alpha, lambda, targets
def test_initial_alpha_is_honoured_under_auto_tuning():
    loss, *_ = make_loss(1)
    assert isinstance(loss.log_alpha, nn.Parameter)
    assert loss.log_alpha.detach().exp().item() == pytest.approx(ALPHA)
    assert float(loss.target_entropy) == -ACT
    out = loss(make_batch())
    assert float(out["alpha"]) == pytest.approx(ALPHA)
    optimizer = torch.optim.Adam([loss.log_alpha], lr=3e-4)
    out["loss_alpha"].backward()
    optimizer.step()
    assert loss.log_alpha.detach().exp().item() != pytest.approx(ALPHA, rel=1e-6)

    fixed, *_ = make_loss(1, fixed_alpha=True, alpha_init=0.2)
    assert not isinstance(fixed.log_alpha, nn.Parameter)
    assert float(fixed(make_batch())["alpha"]) == pytest.approx(0.2)


def test_lagrangian_buffer_setter_and_state_dict():
    loss, *_ = make_loss(2)
    buffer = loss.lagrangian
    assert buffer.shape == (2,) and "lagrangian" in loss.state_dict()
    loss.lagrangian = 0.5
    assert loss.lagrangian.tolist() == [0.5, 0.5]
    loss.lagrangian = [0.1, 0.2]
    assert loss.lagrangian.tolist() == pytest.approx([0.1, 0.2])
    pid = PIDLagrangian(cost_limit=[1.0, 1.0])
    loss.lagrangian = pid.update([3.0, 0.0])  # float64 from the controller
    assert loss.lagrangian.dtype == torch.float32
    assert loss.lagrangian.tolist() == pytest.approx([0.05 * 2 + 0.0005 * 2 + 0.1 * 2, 0.0])
    assert loss.lagrangian is buffer  # updated in place: compiled graphs see the new values
    other, *_ = make_loss(2)
    other.load_state_dict(loss.state_dict())
    assert torch.equal(other.lagrangian, loss.lagrangian)
    for bad, match in (([1.0], "2 values"), (-0.1, ">= 0"), ([0.1, float("nan")], "finite")):
        with pytest.raises(ValueError, match=match):
            loss.lagrangian = bad
    assert loss.lagrangian is buffer


def test_soft_update_covers_cost_critics():
    loss, *_ = make_loss(1)
    updater = SoftUpdate(loss, tau=0.05)
    before = loss.target_cost_qvalue_network_params.clone()
    with torch.no_grad():
        loss.cost_qvalue_network_params.apply(lambda p: p.add_(1.0))
    updater.step()
    expected = before.apply(lambda t, s: 0.95 * t + 0.05 * s, loss.cost_qvalue_network_params)
    for key, value in expected.flatten_keys().items():
        close(loss.target_cost_qvalue_network_params.flatten_keys()[key], value)


@pytest.mark.parametrize("num_costs", [0, 1, 2])
def test_foreach_soft_update_matches_soft_update(num_costs):
    loss, *_ = make_loss(num_costs)
    twin = copy.deepcopy(loss)
    reference, fused = SoftUpdate(loss, tau=0.05), ForeachSoftUpdate(twin, tau=0.05)
    names = ["qvalue_network_params"] + ["cost_qvalue_network_params"] * bool(num_costs)
    before = {name: getattr(loss, "target_" + name).clone() for name in names}
    g = torch.Generator().manual_seed(0)
    for _ in range(3):  # the same parameter moves on both losses, then one update each
        for name in names:
            source = getattr(loss, name).flatten_keys()
            noise = {key: torch.randn(value.shape, generator=g) for key, value in source.items()}
            with torch.no_grad():
                for module in (loss, twin):
                    for key, value in getattr(module, name).flatten_keys().items():
                        value.add_(noise[key])
        reference.step()
        fused.step()
    for name in names:
        target = getattr(loss, "target_" + name).flatten_keys()
        twin_target = getattr(twin, "target_" + name).flatten_keys()
        moved = before[name].flatten_keys()
        assert all(not torch.equal(target[key], moved[key]) for key in target.keys())
        for key, value in target.items():
            close(twin_target[key], value)
    # The actor has no target network: untouched by either updater.
    for key, value in loss.actor_network_params.flatten_keys().items():
        assert torch.equal(twin.actor_network_params.flatten_keys()[key], value)


def test_foreach_soft_update_formula_and_state():
    loss, *_ = make_loss(1)
    updater = ForeachSoftUpdate(loss, tau=0.25)
    target = loss.target_cost_qvalue_network_params
    before = target.clone()
    with torch.no_grad():
        loss.cost_qvalue_network_params.apply(lambda p: p.mul_(-1.0).add_(2.0))
    updater.step()
    expected = before.apply(lambda t, s: 0.75 * t + 0.25 * s, loss.cost_qvalue_network_params)
    for key, value in expected.flatten_keys().items():
        close(target.flatten_keys()[key], value)
    fresh = ForeachSoftUpdate(make_loss(1)[0], tau=0.25)
    fresh.load_state_dict(updater.state_dict())
    assert fresh.initialized and fresh.eps == pytest.approx(0.75)


def test_reduction_none_keeps_the_batch():
    loss, *_ = make_loss(2, reduction="none", scalar_output_mode="exclude")
    out = loss(make_batch(num_costs=2))
    for key in ("loss_actor", "loss_qvalue", "loss_cost_qvalue", "loss_alpha"):
        assert out[key].shape == (32,), key


# --------------------------------------------------------------------------- bad input
def test_wrong_number_of_costs_in_the_data():
    loss, *_ = make_loss(2)
    with pytest.raises(ValueError, match="num_costs=2"):
        loss(make_batch(num_costs=1))
    batch = make_batch(num_costs=2)
    del batch["next", "cost"]
    with pytest.raises(KeyError, match="cost"):
        loss(batch)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"num_costs": 2}, "must hold 4"),
        ({"loss_function": "huber"}, "'l2', 'l1', 'smooth_l1'"),
        ({"reduction": "avg"}, "'mean', 'sum', 'none'"),
        ({"num_costs": -1}, "num_costs"),
        ({"lagrangian_init": [0.1, 0.2]}, "1 values"),
        ({"alpha_init": 0.0}, "alpha_init"),
    ],
)
def test_bad_constructor_arguments(kwargs, match):
    kwargs = {"num_costs": 1, **kwargs}
    with pytest.raises(ValueError, match=match):
        SACLagLoss(make_actor(), make_critics(2), make_critics(2, cost=True), **kwargs)


def test_cost_network_and_num_costs_must_agree():
    with pytest.raises(ValueError, match="needs a cost_qvalue_network"):
        SACLagLoss(make_actor(), make_critics(2), num_costs=1)
    with pytest.raises(ValueError, match="num_costs=0"):
        SACLagLoss(make_actor(), make_critics(2), make_critics(2, cost=True), num_costs=0)


def test_in_and_out_keys():
    loss, *_ = make_loss(2)
    assert ("next", "cost") in loss.in_keys and "observation" in loss.in_keys
    assert set(loss.out_keys) == {
        "loss_actor",
        "loss_qvalue",
        "loss_cost_qvalue",
        "loss_alpha",
        "alpha",
        "entropy",
        "reward_q",
        "cost_q",
        "lagrangian",
    }
    loss.set_keys(cost="penalty")
    assert ("next", "penalty") in loss.in_keys
    batch = make_batch(num_costs=2)
    batch.rename_key_(("next", "cost"), ("next", "penalty"))
    assert loss(batch)["cost_q"].shape == (2,)


@pytest.mark.slow  # torch.compile of the loss: about a minute on a busy 2-core machine
def test_checkpointing_a_compiled_loss_does_not_recompile_it():
    # SACLoss creates its target-entropy buffer on first use, e.g. at the first state_dict; the
    # module then changes under dynamo's guards. SACLagLoss settles it when it is built.
    loss, *_ = make_loss()
    assert dict(loss.named_buffers())["_target_entropy"].item() == -ACT
    compiled = torch.compile(loss)
    batch = make_batch()
    compiled(batch.copy())
    loss.state_dict()
    with torch._dynamo.config.patch(error_on_recompile=True):
        compiled(batch.copy())


@pytest.mark.slow  # torch.compile of the loss
def test_lambda_reaches_a_compiled_loss_without_recompiling():
    # A per-step controller writes lambda after every gradient step: the compiled loss must
    # read the new value (the buffer, set in place) and not recompile for it.
    loss, *_ = make_loss()
    compiled = torch.compile(loss)
    batch = make_batch()
    torch.manual_seed(0)
    compiled(batch.copy())
    outputs = []
    with torch._dynamo.config.patch(error_on_recompile=True):
        for value in (0.5, 3.0, [7.25]):
            loss.set_lagrangian(value)
            torch.manual_seed(0)
            outputs.append(compiled(batch.copy()))
    for value, out in zip((0.5, 3.0, 7.25), outputs):
        assert out["lagrangian"].tolist() == [value]
    torch.manual_seed(0)
    eager = loss(batch.copy())  # lambda 7.25, eager: the same actor loss as compiled
    torch.testing.assert_close(outputs[-1]["loss_actor"], eager["loss_actor"])


# --------------------------------------------------------------------------- sound cost critics
READS = {"min": lambda a, b: torch.minimum(a, b), "max": torch.maximum, "mean": lambda a, b: (a + b) / 2}


@pytest.mark.parametrize("read", ["min", "max", "mean"])
@pytest.mark.parametrize("nonnegative", [False, True])
def test_cost_targets_read_the_pair_as_configured_by_hand(read, nonnegative):
    loss, actor, _, costs = make_loss(
        2, cost_critic_read=read, cost_nonnegative=nonnegative, entropy_in_cost_target=False
    )
    batch = make_batch(num_costs=2, steps=False)
    check_cost_targets(loss, actor, costs, batch, read, nonnegative)


def check_cost_targets(loss, actor, costs, batch, read, nonnegative=False):
    """``loss``'s 1-step cost targets (no entropy term) against the hand formula with the pair
    of each cost read through ``read``, for the same action a' ~ pi(s')."""
    torch.manual_seed(6)
    _, target_c = loss.compute_targets(batch)
    torch.manual_seed(6)
    nxt = batch["next", "observation"]
    a_next, _ = sample(actor, nxt)
    alive = (~batch["next", "terminated"].squeeze(-1)).float()
    q_c = q_values(costs, nxt, a_next)
    for i in range(target_c.shape[-1]):
        v = READS[read](q_c[2 * i], q_c[2 * i + 1])
        if nonnegative:
            v = v.clamp_min(0.0)
        close(target_c[:, i], batch["next", "cost"][:, i] + GAMMA * alive * v, atol=1e-5)


@pytest.mark.parametrize(("actor_read", "target_read"), [("max", "mean"), ("min", "max")])
def test_the_targets_own_read_leaves_the_actor_loss_on_its_read_by_hand(actor_read, target_read):
    # cost_target_read reads the pair in y_i; cost_critic_read keeps the actor loss's read.
    loss, actor, critics, costs = make_loss(
        1, cost_critic_read=actor_read, cost_target_read=target_read,
        entropy_in_cost_target=False, rescaling=False,
    )
    assert (loss.cost_critic_read, loss.cost_target_read) == (actor_read, target_read)
    batch = make_batch(steps=False)
    check_cost_targets(loss, actor, costs, batch, target_read)
    loss.lagrangian = 2.0
    obs = batch["observation"]
    torch.manual_seed(7)
    loss_actor, _ = loss.actor_loss(batch.clone())
    torch.manual_seed(7)
    a, logp = sample(actor, obs)
    q_c = q_values(costs, obs, a)
    q_r = q_values(critics, obs, a).min(0)[0]
    close(loss_actor, (ALPHA * logp - q_r + 2.0 * READS[actor_read](q_c[0], q_c[1])).mean())
    # Without it, the targets read as the actor loss does (what runs before the option did).
    plain, *_ = make_loss(1, cost_critic_read=actor_read)
    assert plain.cost_target_read == actor_read


def test_nonnegative_cost_values_clamp_a_negative_critic():
    # Biases of -5 make every cost value negative: the target then is the cost itself, and the
    # actor's penalty term is 0 (no gradient pulls the policy towards a negative cost value).
    loss, *_ = make_loss(1, cost_nonnegative=True, entropy_in_cost_target=False)
    last_bias = [k for k in loss.cost_qvalue_network_params.flatten_keys().keys() if "bias" in k][-1]
    with torch.no_grad():
        loss.cost_qvalue_network_params.flatten_keys()[last_bias].fill_(-5.0)
        loss.target_cost_qvalue_network_params.flatten_keys()[last_bias].fill_(-5.0)
    batch = make_batch(steps=False)
    _, target_c = loss.compute_targets(batch)
    close(target_c, batch["next", "cost"])
    loss.lagrangian = 1.0
    terms = loss.actor_loss_terms(batch.clone())
    assert terms["cost"].item() == 0.0


@pytest.mark.parametrize("entropy_rescaling", [True, False])
def test_entropy_rescaling_by_hand(entropy_rescaling):
    loss, actor, critics, costs = make_loss(
        1, rescaling=True, entropy_rescaling=entropy_rescaling, cost_critic_read="max"
    )
    loss.lagrangian = 3.0
    batch = make_batch()
    obs = batch["observation"]
    torch.manual_seed(7)
    loss_actor, _ = loss.actor_loss(batch.clone())
    torch.manual_seed(7)
    a, logp = sample(actor, obs)
    q_c = q_values(costs, obs, a).max(0)[0]
    q_r = q_values(critics, obs, a).min(0)[0]
    if entropy_rescaling:  # FSRL: the whole loss over 1 + lambda
        expected = (ALPHA * logp - q_r + 3.0 * q_c).mean() / 4.0
    else:  # alpha's term outside the rescaling
        expected = (ALPHA * logp).mean() + (3.0 * q_c - q_r).mean() / 4.0
    close(loss_actor, expected)
    # The terms the diagnostics read add up to the same loss, for the same random draw.
    torch.manual_seed(7)
    terms = loss.actor_loss_terms(batch.clone())
    close(sum(terms.values()), expected)
    scale = 4.0 if entropy_rescaling else 1.0
    close(terms["entropy"], (ALPHA * logp).mean() / scale)
    close(terms["cost"], 3.0 * q_c.mean() / 4.0)


def test_default_is_fsrl_and_bad_read_is_refused():
    loss, *_ = make_loss(1)
    assert (loss.cost_critic_read, loss.cost_nonnegative, loss.entropy_rescaling) == (
        "min",
        False,
        True,
    )
    with pytest.raises(ValueError, match="cost_critic_read 'median'.*'min', 'max', 'mean'"):
        make_loss(1, cost_critic_read="median")
    with pytest.raises(ValueError, match="cost_target_read 'upper'.*'min', 'max', 'mean'"):
        make_loss(1, cost_target_read="upper")


def test_critic_values_are_the_current_critics():
    loss, _, critics, costs = make_loss(2)
    batch = make_batch(num_costs=2)
    q_r, q_c = loss.critic_values(batch)
    close(q_r, q_values(critics, batch["observation"], batch["action"]))
    close(q_c.flatten(0, 1), q_values(costs, batch["observation"], batch["action"]))
