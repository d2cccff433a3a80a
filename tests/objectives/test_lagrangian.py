"""Lagrangian controllers against hand-computed sequences."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from s3rl_torchrl.objectives import LearnedLagrangian, PIDLagrangian


def run(controller, costs):
    return [controller.update(cost).tolist() for cost in costs]


def test_pid_fsrl_form_by_hand():
    pid = PIDLagrangian(kp=0.05, ki=0.0005, kd=0.1, cost_limit=10.0)
    assert pid.lagrangian.tolist() == [0.0]
    # e = J - 10; I = max(0, I + e); D = max(0, e - e_prev), e_prev starting at 0
    #  J=12: e=2,  I=2,  D=2   -> 0.1 + 0.001 + 0.2        = 0.301
    #  J=15: e=5,  I=7,  D=3   -> 0.25 + 0.0035 + 0.3      = 0.5535
    #  J=8:  e=-2, I=5,  D=0   -> -0.1 + 0.0025            < 0 -> 0
    #  J=3:  e=-7, I=0,  D=0   -> -0.35                    < 0 -> 0
    #  J=20: e=10, I=10, D=17  -> 0.5 + 0.005 + 1.7        = 2.205
    #  J=10: e=0,  I=10, D=0   -> 0.005
    out = run(pid, [12.0, 15.0, 8.0, 3.0, 20.0, 10.0])
    expected = [0.301, 0.5535, 0.0, 0.0, 2.205, 0.005]
    assert [o[0] for o in out] == pytest.approx(expected, abs=1e-12)
    assert pid.lagrangian.tolist() == pytest.approx([0.005], abs=1e-12)
    assert int(pid.num_updates) == 6


def test_pid_rlpyt_options_by_hand():
    pid = PIDLagrangian(
        kp=0.1,
        ki=0.01,
        kd=0.2,
        cost_limit=5.0,
        ki_inside_integral=True,
        error_ema=0.5,
        cost_ema=0.5,
        derivative_delay=2,
        derivative_history_init="zero",
        penalty_max=1.0,
    )
    # P = .5 P + .5 e; I = max(0, I + .01 e); C = .5 C + .5 J; D = max(0, C - C two updates ago)
    #  J=9:  e=4,  P=2,    I=.04, C=4.5,    D=4.5-0     -> .2+.04+.9   = 1.14 -> cap 1.0
    #  J=13: e=8,  P=5,    I=.12, C=8.75,   D=8.75-0    -> .5+.12+1.75 = 2.37 -> cap 1.0
    #  J=1:  e=-4, P=.5,   I=.08, C=4.875,  D=4.875-4.5 -> .05+.08+.075 = .205
    #  J=5:  e=0,  P=.25,  I=.08, C=4.9375, D=0 (< 8.75) -> .025+.08   = .105
    out = run(pid, [9.0, 13.0, 1.0, 5.0])
    assert [o[0] for o in out] == pytest.approx([1.0, 1.0, 0.205, 0.105], abs=1e-12)


def test_pid_two_costs_have_their_own_state():
    pid = PIDLagrangian(cost_limit=[10.0, 2.0])
    # cost 0 as in the FSRL test; cost 1: J=1: e=-1 -> 0; J=4: e=2, I=2, D=2-(-1)=3 -> 0.401
    out = run(pid, [[12.0, 1.0], [15.0, 4.0]])
    assert out[0] == pytest.approx([0.301, 0.0], abs=1e-12)
    assert out[1] == pytest.approx([0.5535, 0.401], abs=1e-12)


def test_pid_scalar_limit_broadcasts_to_num_costs():
    pid = PIDLagrangian(cost_limit=10.0, num_costs=2)
    assert pid.cost_limit.tolist() == [10.0, 10.0]
    assert pid.update(torch.tensor([12.0, 8.0])).tolist() == pytest.approx([0.301, 0.0])


def test_pid_lagrangian_init_seeds_the_integral():
    pid = PIDLagrangian(cost_limit=10.0, lagrangian_init=0.2)
    assert pid.lagrangian.tolist() == pytest.approx([0.2])
    # e = 0: only the integral term remains, ki * (0.2 / ki) = 0.2
    assert pid.update(10.0).tolist() == pytest.approx([0.2], abs=1e-12)


def test_pid_state_dict_round_trip_continues_identically():
    options = {"error_ema": 0.3, "cost_ema": 0.6, "derivative_delay": 3, "ki_inside_integral": True}
    a = PIDLagrangian(cost_limit=[5.0, 1.0], **options)
    run(a, [[6.0, 0.0], [9.0, 3.0], [2.0, 2.0]])
    b = PIDLagrangian(cost_limit=[5.0, 1.0], **options)
    b.load_state_dict(a.state_dict())
    assert torch.equal(b.lagrangian, a.lagrangian)
    later = [[7.0, 1.0], [1.0, 5.0], [8.0, 0.5]]
    assert run(b, later) == run(a, later)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cost_limit": -1.0}, "cost_limit"),
        ({"cost_limit": float("inf")}, "cost_limit"),
        ({"cost_limit": [1.0, 2.0], "num_costs": 3}, "one per cost"),
        ({"kp": -0.1}, "kp"),
        ({"error_ema": 1.0}, "error_ema"),
        ({"derivative_delay": 0}, "derivative_delay"),
        ({"derivative_history_init": "last"}, "limit, zero"),
        ({"penalty_max": 0.0}, "penalty_max"),
        ({"ki": 0.0, "lagrangian_init": 0.5}, "ki > 0"),
    ],
)
def test_pid_bad_arguments(kwargs, match):
    kwargs = {"cost_limit": 10.0, **kwargs}
    with pytest.raises(ValueError, match=match):
        PIDLagrangian(**kwargs)


def test_update_rejects_wrong_length_and_nan():
    pid = PIDLagrangian(cost_limit=[1.0, 2.0])
    with pytest.raises(ValueError, match="2 cost limit"):
        pid.update(3.0)
    with pytest.raises(ValueError, match="finite"):
        pid.update([float("nan"), 1.0])
    assert int(pid.num_updates) == 0


def test_learned_lagrangian_adam_steps_by_hand():
    lag = LearnedLagrangian(cost_limit=10.0, lr=0.1, lagrangian_init=0.5)
    # Loss -lambda (J - d): gradient -(J - d). Adam's first steps with a constant gradient move
    # by exactly lr (m_hat / sqrt(v_hat) = sign(g)), up the constraint violation.
    assert lag.update(12.0).tolist() == pytest.approx([0.6], abs=1e-6)
    assert lag.update(12.0).tolist() == pytest.approx([0.7], abs=1e-6)
    # Third step, gradient +10 (J = 0): Adam's update written out.
    b1, b2 = 0.9, 0.999
    m = v = 0.0
    for g in (-2.0, -2.0, 10.0):
        m, v = b1 * m + (1 - b1) * g, b2 * v + (1 - b2) * g * g
    step = 0.1 * (m / (1 - b1**3)) / (math.sqrt(v / (1 - b2**3)) + 1e-8)
    assert lag.update(0.0).tolist() == pytest.approx([0.7 - step], abs=1e-6)


def test_learned_lagrangian_clamps_at_zero_and_upper_bound():
    lag = LearnedLagrangian(cost_limit=[10.0, 0.0], lr=0.5, lagrangian_init=0.3, upper_bound=1.0)
    for _ in range(5):
        out = lag.update([0.0, 50.0])
    assert out.tolist() == [0.0, 1.0]
    assert bool((lag.multiplier >= 0).all())


def test_learned_lagrangian_state_dict_includes_adam_state():
    a = LearnedLagrangian(cost_limit=[3.0, 4.0], lr=0.05)
    run(a, [[5.0, 1.0], [4.0, 6.0]])
    b = LearnedLagrangian(cost_limit=[3.0, 4.0], lr=0.05)
    b.load_state_dict(a.state_dict())
    later = [[1.0, 9.0], [7.0, 2.0], [3.5, 4.5]]
    assert run(b, later) == run(a, later)


def test_learned_lagrangian_bad_arguments():
    with pytest.raises(ValueError, match="lr"):
        LearnedLagrangian(cost_limit=1.0, lr=0.0)
    with pytest.raises(ValueError, match="lagrangian_init"):
        LearnedLagrangian(cost_limit=1.0, lagrangian_init=-1.0)
    with pytest.raises(ValueError, match="cost_limit"):
        LearnedLagrangian(cost_limit=-2.0)


# ------------------------------------------------------------------ controllers in a closed loop
# A synthetic plant for the policy: the cost of the next collect falls linearly with the
# multiplier in force while the policy trains, J_{t+1} = max(0, J0 - k lambda_t) (+ noise).
# J0 = 900 and k = 486 fit the cycling SAC-Lag run on HalfCheetah (J ~ 900 at lambda ~ 0,
# ~ 270 at lambda 1.3): the cost that meets the limit d = 10 needs lambda* = 890 / 486 = 1.83.
PLANT = {"J0": 900.0, "k": 486.0}
LIMIT = 10.0
# configs/pid/ema.yaml: the paper's gains with OmniSafe's damping options.
DAMPED = {"error_ema": 0.95, "cost_ema": 0.95, "derivative_delay": 10}


def closed_loop(controller, updates, J0, k, noise=0.0, seed=0):
    """Costs fed to the controller and the multipliers it returned, one entry per update."""
    rng = np.random.default_rng(seed)
    lam, costs, lams = float(controller.lagrangian[0]), [], []
    for _ in range(updates):
        cost = max(0.0, J0 - k * lam + noise * rng.standard_normal())
        lam = float(controller.update(cost)[0])
        costs.append(cost)
        lams.append(lam)
    return np.array(costs), np.array(lams)


def test_fsrl_pid_on_a_steep_plant_is_a_period_two_cycle():
    kp, ki, kd = 0.05, 0.0005, 0.1
    costs, lams = closed_loop(PIDLagrangian(kp, ki, kd, LIMIT), 400, **PLANT)
    # By hand: J=900: e=890, I=890, D=890 -> 44.5 + 0.445 + 89 = 133.945 -> next J = 0
    #          J=0:   e=-10, I=880, D=0   -> -0.5 + 0.44 < 0 -> 0          -> next J = 900
    #          J=900: e=890, I=1770, D=900 -> 44.5 + 0.885 + 90 = 135.385
    #          J=0:   e=-10, I=1760        -> -0.5 + 0.88 = 0.38           -> next J = 715.32
    assert lams[:4] == pytest.approx([133.945, 0.0, 135.385, 0.38], abs=1e-9)
    assert costs[4] == pytest.approx(900 - 486 * 0.38)
    # Over the limit and at zero in turn, for all 400 updates: the high lambda of one update
    # (kp + kd = 0.15 per unit of excess cost) stops the plant, the next has only the integral.
    assert (costs[1::2] == 0).all() and (costs[0::2] > LIMIT).all()
    # After a J = 0 collect, e = -d and D = 0: lambda = ki * sum(e) - kp * d (the running sum of
    # errors stays positive, so the integral never clamps).
    integral = np.cumsum(costs - LIMIT)
    assert (integral > 0).all()
    low = np.maximum(0.0, ki * integral - kp * LIMIT)[1::2]
    assert lams[1::2] == pytest.approx(low, abs=1e-9)
    # The cycle the formula settles in: the integral stops moving when the errors cancel over a
    # period, e_high = -e_low = d, i.e. J alternates 2d and 0 (mean J = d, never within the
    # limit twice in a row); lambda jumps by 2d (kp + kd) + d ki = 3.005 at every update.
    assert costs[-20::2] == pytest.approx(np.full(10, 2 * LIMIT), abs=1e-3)
    jumps = np.abs(np.diff(lams[-20:]))
    assert jumps == pytest.approx(np.full(19, 2 * LIMIT * (kp + kd) + LIMIT * ki), abs=1e-3)


def test_damped_pid_on_the_same_plant_settles_without_cycling():
    costs, lams = closed_loop(PIDLagrangian(0.05, 0.0005, 0.1, LIMIT, **DAMPED), 400, **PLANT)
    # First update: P = 0.05 * 890, C = 0.95 d + 0.05 * 900 = 54.5 against d 10 updates back:
    # 0.05 * 44.5 + 0.0005 * 890 + 0.1 * 44.5 = 7.12 (vs 133.9 undamped).
    assert lams[0] == pytest.approx(0.05 * 44.5 + 0.0005 * 890 + 0.1 * 44.5, abs=1e-9)
    # The EMAs hold lambda up while the delayed derivative window passes (10 updates at J = 0),
    # then it is at the plant's lambda* and moves less every update: no cycle.
    assert (costs[1:11] == 0).all()
    jumps = np.abs(np.diff(lams[40:]))
    assert jumps.max() < 0.001 and (np.diff(jumps[::10]) <= 0).all()
    # From above, monotonically: the integral alone closes the offset the P term leaves
    # (slowly: ~1 % of it per update), reaching the limit within 10 % in 400 updates.
    assert (np.diff(costs[40:]) <= 1e-9).all()
    assert LIMIT <= costs[-1] <= 1.1 * LIMIT


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_damping_removes_the_cycle_on_a_noisy_plant(seed):
    """Same plant, 20 cost units of noise per collect, 100 updates (the paper's 1M frames at
    10000 per collect); second half: the damped lambda moves 10x less and its mean is within
    10 % of lambda*, FSRL's keeps swinging by the noise times (kp + kd) k."""
    lam_star = (PLANT["J0"] - LIMIT) / PLANT["k"]
    fsrl = closed_loop(PIDLagrangian(cost_limit=LIMIT), 100, **PLANT, noise=20.0, seed=seed)
    damped = closed_loop(
        PIDLagrangian(cost_limit=LIMIT, **DAMPED), 100, **PLANT, noise=20.0, seed=seed
    )
    swing_fsrl = np.abs(np.diff(fsrl[1][50:])).mean()
    swing_damped = np.abs(np.diff(damped[1][50:])).mean()
    assert swing_fsrl > 1.0 and swing_damped < 0.1 * swing_fsrl
    assert damped[1][50:].mean() == pytest.approx(lam_star, rel=0.1)


def test_a_stronger_integral_closes_the_offset_the_damped_pid_leaves():
    """A flatter plant (k = 100, lambda* = 8.9), no noise, 50 updates (1M frames at one update
    per 20 000-frame collect): with FSRL's ki the damped PID is nearly a P controller and the
    cost stays far over the limit; with ki = 0.01 (research/studies/lagrangian_dynamics.py
    pid_ema_ki0.01) it overshoots once, then settles at lambda* with the cost just over d."""
    plant = {"J0": 900.0, "k": 100.0}
    lam_star = (plant["J0"] - LIMIT) / plant["k"]
    weak_costs, _ = closed_loop(PIDLagrangian(0.05, 0.0005, 0.1, LIMIT, **DAMPED), 50, **plant)
    costs, lams = closed_loop(PIDLagrangian(0.05, 0.01, 0.1, LIMIT, **DAMPED), 50, **plant)
    assert weak_costs[25:].mean() > 5 * LIMIT
    # First update, by hand: 0.05 * 44.5 + 0.01 * 890 + 0.1 * 44.5 (the integral's 8.9 alone
    # is lambda*), so the plant stops until the EMAs and the delayed derivative let go.
    assert lams[0] == pytest.approx(0.05 * 44.5 + 0.01 * 890 + 0.1 * 44.5, abs=1e-9)
    assert (costs[1:12] == 0).all()
    # Then over the limit but falling (monotonically from the 15th update), to within 20 % of
    # it by update 50; lambda at lambda* and no longer moving.
    assert (costs[12:] >= LIMIT).all() and (np.diff(costs[14:]) <= 1e-9).all()
    assert costs[-1] <= 1.2 * LIMIT
    assert np.abs(np.diff(lams[25:])).max() < 0.001
    assert lams[25:].mean() == pytest.approx(lam_star, rel=0.01)


def test_learned_lagrangian_on_the_plant_climbs_by_lr_and_settles():
    lr = 0.05
    costs, lams = closed_loop(LearnedLagrangian(LIMIT, lr=lr, lagrangian_init=0.0), 200, **PLANT)
    # While the constraint is violated the gradient -(J - d) keeps its sign and Adam steps by
    # m_hat / sqrt(v_hat) * lr: lr while |J - d| barely shrinks, less as it does.
    steps = np.diff(np.concatenate([[0.0], lams]))
    assert steps[:10] == pytest.approx(np.full(10, lr), rel=0.05)
    assert (costs[:50] > LIMIT).all() and (steps[:50] > 0).all()
    # It settles at lambda* with steps of at most lr: no cycle of the PID's size.
    lam_star = (PLANT["J0"] - LIMIT) / PLANT["k"]
    assert np.abs(steps).max() <= lr * 1.001
    assert lams[-50:].mean() == pytest.approx(lam_star, rel=0.05)


# ------------------------------------------------------------------ cadence: window and updater
def test_learned_lagrangian_matches_torch_adam():
    # The hand-written Adam against torch.optim.Adam on the same loss -lambda (J - d), clamped
    # at 0 after each step, as OmniSafe's Lagrange does (float32 parameter there).
    from s3rl_torchrl.objectives import LearnedLagrangian

    costs = [40.0, 40.0, 3.0, 25.0, 0.0, 0.0, 0.0, 12.0, 9.0, 60.0] * 3
    lag = LearnedLagrangian(cost_limit=10.0, lr=0.05, lagrangian_init=0.01)
    multiplier = torch.nn.Parameter(torch.tensor(0.01, dtype=torch.float64))
    adam = torch.optim.Adam([multiplier], lr=0.05)
    for cost in costs:
        adam.zero_grad()
        (-multiplier * (cost - 10.0)).backward()
        adam.step()
        with torch.no_grad():
            multiplier.clamp_(min=0.0)
        assert lag.update(cost).item() == pytest.approx(multiplier.item(), abs=1e-12)


def test_episode_cost_window_mean_by_hand():
    from s3rl_torchrl.objectives import EpisodeCostWindow

    window = EpisodeCostWindow(3)
    assert window.mean() is None and len(window) == 0
    window.extend(torch.zeros(0, 1))  # a batch in which no episode ended
    assert window.mean() is None
    window.extend(torch.tensor([[4.0], [8.0]]))
    assert window.mean() == [6.0]
    window.extend([[30.0], [1.0]])  # 4 drops out: (8 + 30 + 1) / 3
    assert window.mean() == pytest.approx([13.0]) and len(window) == 3
    copy = EpisodeCostWindow(3)
    copy.load_state_dict(window.state_dict())
    copy.extend([[2.0]])
    window.extend([[2.0]])
    assert copy.mean() == window.mean() == pytest.approx([11.0])
    with pytest.raises(ValueError, match="window size"):
        EpisodeCostWindow(0)


class _Loss(torch.nn.Module):
    """A loss with a lagrangian buffer (the mixin SACLagLoss uses)."""

    def __new__(cls):
        from s3rl_torchrl.objectives._lagrangian_buffer import LagrangianBufferMixin

        kind = type("LagLoss", (LagrangianBufferMixin, torch.nn.Module), {})
        loss = kind()
        loss.num_costs = 1
        loss._init_lagrangian(0.0)
        return loss


def test_updater_collect_cadence_warmup_and_batches_without_episodes():
    from s3rl_torchrl.objectives import LagrangianUpdater

    loss = _Loss()
    updater = LagrangianUpdater(PIDLagrangian(cost_limit=10.0), loss, warmup_frames=1000)
    assert updater.observe(torch.tensor([[12.0]]), 1000) is None  # warm-up: not past 1000
    assert float(loss.lagrangian) == 0.0
    assert updater.observe(torch.zeros(0, 1), 2000) is None  # no episode ended
    assert updater.observe(torch.tensor([[12.0], [16.0]]), 3000) == [14.0]
    # FSRL's first update from J = 14: 0.05 * 4 + 0.0005 * 4 + 0.1 * 4
    assert float(loss.lagrangian) == pytest.approx(0.602, abs=1e-6)
    assert not updater.after_gradient_step()  # collect cadence: nothing per step
    assert updater.controller.num_updates == 1


def test_updater_step_cadence_by_hand():
    from s3rl_torchrl.objectives import LagrangianUpdater

    loss = _Loss()
    pid = PIDLagrangian(kp=0.0, ki=0.01, kd=0.0, cost_limit=10.0)
    updater = LagrangianUpdater(pid, loss, cadence="step", window=2, warmup_frames=100)
    assert updater.observe(torch.tensor([[30.0]]), 100) == [30.0]  # the window, not an update
    assert not updater.after_gradient_step()  # warm-up: frames not past 100
    updater.observe(torch.zeros(0, 1), 200)
    assert updater.after_gradient_step() and updater.after_gradient_step()
    # Two steps from J = 30: integral 20, 40 -> lambda 0.4
    assert float(loss.lagrangian) == pytest.approx(0.4)
    updater.observe(torch.tensor([[0.0], [2.0]]), 300)  # window (0 + 2) / 2 = 1: e = -9
    updater.after_gradient_step()
    assert float(loss.lagrangian) == pytest.approx(0.31)
    # state_dict: the controller, the window and the frame count (the warm-up's clock).
    other = LagrangianUpdater(
        PIDLagrangian(kp=0.0, ki=0.01, kd=0.0, cost_limit=10.0), _Loss(),
        cadence="step", window=2, warmup_frames=100,
    )
    other.load_state_dict(updater.state_dict())
    assert other.window.mean() == [1.0] and not other.warming_up
    assert other.after_gradient_step() and updater.after_gradient_step()
    assert other.lagrangian.tolist() == updater.lagrangian.tolist() == pytest.approx([0.22])
    with pytest.raises(ValueError, match="collect, step"):
        LagrangianUpdater(pid, loss, cadence="epoch")


def test_updater_eval_window_follows_the_larger_of_training_and_evaluation_cost():
    # The delivered (deterministic) policy's cost joins lambda's signal: J is the larger of the
    # training window's mean and the mean of the last `eval_window` evaluation episodes.
    from s3rl_torchrl.objectives import LagrangianUpdater

    def updater(eval_window):
        pid = PIDLagrangian(kp=0.0, ki=0.01, kd=0.0, cost_limit=10.0)
        return LagrangianUpdater(pid, _Loss(), cadence="step", window=2, eval_window=eval_window)

    plain, aimed = updater(0), updater(3)
    for each in (plain, aimed):
        each.observe(torch.tensor([[6.0], [8.0]]), 100)  # training mean 7, below the limit
    assert aimed.signal([7.0]) == [7.0]  # no evaluation yet: the training mean alone
    plain.observe_evaluation([[40.0]])  # ignored without an evaluation window
    assert plain.evaluation_window is None
    aimed.observe_evaluation([[14.0], [16.0]])  # mean 15 > 7
    assert aimed.signal([7.0]) == [15.0] and aimed.signal([20.0]) == [20.0]
    assert plain.after_gradient_step() and aimed.after_gradient_step()
    # integral max(0, 7 - 10) = 0 for the training signal; 15 - 10 = 5 -> lambda 0.05.
    assert float(plain.lagrangian) == 0.0
    assert float(aimed.lagrangian) == pytest.approx(0.05)
    aimed.observe_evaluation([[0.0], [2.0]])  # window 16, 0, 2: mean 6 -> J = max(7, 6) = 7
    assert aimed.signal([7.0]) == [7.0]
    # The collect cadence takes the same signal: a batch's mean 8 against the window's 6.
    collect = LagrangianUpdater(PIDLagrangian(cost_limit=10.0), _Loss(), eval_window=2)
    collect.observe_evaluation([[12.0], [14.0]])
    assert collect.observe(torch.tensor([[8.0]]), 100) == [13.0]
    # The evaluation window is checkpointed with the rest.
    other = updater(3)
    other.load_state_dict(aimed.state_dict())
    assert other.evaluation_window.mean() == aimed.evaluation_window.mean() == [6.0]
    with pytest.raises(ValueError, match="eval_window"):
        updater(-1)
