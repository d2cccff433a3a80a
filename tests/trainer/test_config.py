"""Config schemas: every YAML is type-checked, bad values fail before training, naming the field."""

from __future__ import annotations

import pytest
from hydra.errors import ConfigCompositionException
from omegaconf.errors import ValidationError

from s3rl_torchrl.algorithms import ALGORITHMS, DDPGConfig, PPOConfig, SACConfig, family_of
from s3rl_torchrl.algorithms.schedule import OffPolicySchedule, OnPolicySchedule
from s3rl_torchrl.envs import task_names
from s3rl_torchrl.trainer import ConfigError, TrainConfig, validate
from s3rl_torchrl.trainer.config import ALGO_NAMES


def schedule_of(cfg):
    return family_of(cfg.algo).schedule(cfg.collector, cfg.algo)


def test_defaults_are_quick_s3rl_on_half_cheetah(compose):
    cfg = validate(compose())
    assert cfg.task.name == "SafetyHalfCheetahVelocity-v1"
    assert cfg.algo.name == "s3rl" and cfg.algo.contrastive
    # The quick run keeps its limit on every seed (docs/recipes.md): the per-step learned
    # multiplier and the sound critics (configs/experiment/quick.yaml).
    assert (cfg.algo.lagrangian, cfg.algo.lagrangian_cadence) == ("learned", "step")
    assert (cfg.algo.cost_critic_read, cfg.algo.entropy_rescaling) == ("max", False)
    unconstrained = validate(compose("algo=sac"))
    assert unconstrained.algo.lagrangian == "none"


@pytest.mark.parametrize("algo", ALGO_NAMES)
@pytest.mark.parametrize("experiment", ["quick", "paper", "tiny"])
def test_every_algo_and_experiment_composes(algo, experiment, compose):
    cfg = validate(compose(f"algo={algo}", f"experiment={experiment}"))
    assert cfg.algo.name == algo
    expect_lag = algo in ("s3rl", "sac_lag", "ddpg_lag", "s3rl_ddpg_lag", "ppo_lag", "s3rl_ppo_lag")
    assert (cfg.algo.lagrangian != "none") == expect_lag
    assert cfg.algo.contrastive == algo.startswith("s3rl")
    family = "ddpg" if "ddpg" in algo else "ppo" if "ppo" in algo else "sac"
    assert family_of(cfg.algo).name == family == ALGORITHMS[algo].family.name
    # Each family's config class, with its own fields only.
    assert type(cfg.algo) is {"sac": SACConfig, "ddpg": DDPGConfig, "ppo": PPOConfig}[family]
    assert hasattr(cfg.algo, "update_order") == (family == "sac")
    assert hasattr(cfg.algo, "n_step") == (family != "ppo")
    assert isinstance(schedule_of(cfg), OnPolicySchedule if family == "ppo" else OffPolicySchedule)


@pytest.mark.parametrize("algo", ["ppo_lag", "ppo", "s3rl_ppo_lag"])
def test_ppo_family_has_fsrl_ppo_lag_defaults(algo, compose):
    # fsrl/config/ppol_cfg.py: lr 5e-4 (one Adam), gamma 0.99, gae_lambda 0.95, eps_clip 0.2,
    # vf_coef 0.25, max_grad_norm 0.5, repeat_per_collect 4, batch_size 256, rescaling.
    a = validate(compose(f"algo={algo}")).algo
    assert (a.actor_lr, a.critic_lr, a.gamma, a.gae_lambda, a.clip_epsilon) == (
        5e-4, 5e-4, 0.99, 0.95, 0.2,
    )
    assert (a.critic_coeff, a.max_grad_norm, a.ppo_epochs, a.batch_size, a.rescaling) == (
        0.25, 0.5, 4, 256, True,
    )
    assert a.cost_surrogate == "unclipped" and (a.pid.kp, a.pid.ki, a.pid.kd) == (0.05, 5e-4, 0.1)


def test_ddpg_options_are_checked(compose):
    with pytest.raises(ConfigError, match="'algo.exploration_noise'"):
        validate(compose("algo=ddpg", "algo.exploration_noise=-0.1"))
    # DDPG steps in FSRL's order only: it has no update_order to set.
    with pytest.raises(ConfigCompositionException):
        compose("algo=ddpg_lag", "algo.update_order=joint")


@pytest.mark.parametrize(
    ("algo", "field"),
    [
        ("ppo_lag", "algo.n_step=3"),
        ("ppo", "algo.alpha_lr=1e-3"),
        ("ddpg_lag", "algo.ppo_epochs=2"),
        ("sac_lag", "algo.exploration_noise=0.2"),
        ("ddpg_lag", "algo.cost_critic_read=max"),
    ],
)
def test_a_field_of_another_family_is_refused_at_composition(algo, field, compose):
    with pytest.raises(ConfigCompositionException) as err:
        compose(f"algo={algo}", field)
    assert field.split("=")[0].split(".")[1] in str(err.value)


def test_the_sound_critics_are_the_sac_familys(compose):
    cfg = validate(compose("algo=sac_lag", "critic=sound"))
    assert (cfg.algo.cost_critic_read, cfg.algo.cost_nonnegative) == ("max", True)
    assert (cfg.algo.cost_entropy, cfg.algo.entropy_rescaling) == (False, False)
    # experiment=paper has FSRL's (the default critic=fsrl, SACConfig's defaults); the default
    # experiment=quick picks the sound ones.
    paper = validate(compose("algo=sac_lag", "experiment=paper")).algo
    assert paper == validate(compose("algo=sac_lag", "experiment=paper", "critic=fsrl")).algo
    assert paper.cost_critic_read == "min" and paper.entropy_rescaling
    assert validate(compose("algo=sac_lag")).algo.cost_critic_read == "max"
    # The other families have no cost-critic pair: they ignore the choice (a preset sets it
    # whatever the algorithm), and their config has none of its fields.
    ppo = validate(compose("algo=ppo_lag", "critic=sound"))
    assert not hasattr(ppo.algo, "cost_critic_read")


def test_the_cost_targets_own_read_is_a_choice_of_the_sac_family(compose):
    # Unset in both critic sets: the targets read the pair as the actor loss does.
    for critic in ("sound", "fsrl"):
        assert validate(compose("algo=sac_lag", f"critic={critic}")).algo.cost_target_read is None
    split = validate(compose("algo=s3rl", "experiment=safe", "algo.cost_target_read=mean")).algo
    assert (split.cost_critic_read, split.cost_target_read) == ("max", "mean")
    with pytest.raises(ConfigError, match="'algo.cost_target_read'.*min, max, mean"):
        validate(compose("algo=sac_lag", "algo.cost_target_read=upper"))


def test_an_algorithm_name_with_another_familys_yaml_is_refused(compose):
    # algo=s3rl composes the SAC family's config; renaming it to a PPO algorithm does not make
    # it one.
    with pytest.raises(ConfigError, match="'algo.name'.*PPO algorithm.*algo=ppo_lag"):
        validate(compose("algo=s3rl", "algo.name=ppo_lag"))
    with pytest.raises(ConfigError, match="'algo.name': allowed values are s3rl"):
        validate(compose("algo.name=trpo"))


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        (("algo=ppo_lag", "algo.ppo_epochs=0"), "'algo.ppo_epochs'"),
        (("algo=ppo_lag", "algo.gae_lambda=1.5"), "'algo.gae_lambda'"),
        (("algo=ppo", "algo.clip_epsilon=0"), "'algo.clip_epsilon'"),
        (("algo=ppo", "algo.max_grad_norm=0"), "'algo.max_grad_norm'"),
        (("algo=ppo_lag", "algo.cost_surrogate=both"), "'algo.cost_surrogate'.*unclipped"),
    ],
)
def test_ppo_options_are_checked(overrides, match, compose):
    with pytest.raises(ConfigError, match=match):
        validate(compose(*overrides))


@pytest.mark.parametrize("task", task_names())
def test_every_registered_task_is_a_config_option(task, compose):
    assert validate(compose(f"task={task}")).task.name == task


def test_paper_experiment_matches_table_3(compose):
    cfg = validate(compose("experiment=paper"))
    c, a = cfg.collector, cfg.algo
    assert (c.total_frames, c.num_envs, cfg.eval.num_envs) == (1_000_000, 10, 2)
    # FSRL's collect of episode_per_collect = 20 episodes of 1000 steps over the 10 envs: one
    # lambda update and 0.2 x 20000 gradient steps per collect, one collect per epoch.
    assert (c.frames_per_batch, c.frames_per_epoch) == (20 * 1000, 20 * 1000)
    assert (a.batch_size, a.update_per_step, a.buffer_size, a.n_step) == (256, 0.2, 100_000, 2)
    assert (a.actor_lr, a.critic_lr, a.alpha_lr, a.alpha_init, a.tau, a.gamma) == (
        5e-4, 1e-3, 3e-4, 0.005, 0.05, 0.99,
    )
    assert (a.pid.kp, a.pid.ki, a.pid.kd) == (0.05, 0.0005, 0.1)
    assert (a.contrastive_cfg.update_interval, a.contrastive_cfg.steps) == (1000, 50)
    assert a.contrastive_cfg.temperature == 0.7 and a.rescaling
    assert cfg.network.actor_hidden == [128, 128] and cfg.save_interval == 4
    assert cfg.task.cost_limit == 10.0
    assert c.init_random_frames == 20_000  # one collect: FSRL has no warm-up


# FSRL's collect is 20 whole episodes and its epoch whole collects until step_per_epoch = 10000
# frames: (task, episode length from docs/tasks.md, frames per collect, frames per epoch).
@pytest.mark.parametrize(
    ("task", "collect", "epoch"),
    [
        ("SafetyHalfCheetahVelocity-v1", 20 * 1000, 20_000),  # one collect per epoch
        ("SafetyBallRun-v0", 20 * 100, 10_000),  # five collects
        ("SafetyDroneRun-v0", 20 * 200, 12_000),  # three collects: 8000 < 10000 <= 12000
        ("SafetyPointCircle1-v0", 20 * 500, 10_000),  # one collect
    ],
)
def test_paper_collects_are_fsrl_episode_collects_per_task(task, collect, epoch, compose):
    c = validate(compose("experiment=paper", f"task={task}")).collector
    assert (c.frames_per_batch, c.frames_per_epoch, c.init_random_frames) == (collect, epoch, collect)


def test_paper_collect_follows_an_override_of_the_batch(compose):
    c = validate(compose("experiment=paper", "collector.frames_per_batch=4000")).collector
    assert (c.frames_per_batch, c.frames_per_epoch, c.init_random_frames) == (4000, 12_000, 4000)


def test_pid_options_fsrl_by_default_and_the_damped_ema(compose):
    from s3rl_torchrl.algorithms import build_lagrangian
    from s3rl_torchrl.objectives import PIDLagrangian

    for overrides in [(), ("pid=fsrl",), ("experiment=paper", "algo=sac_lag")]:
        pid = validate(compose(*overrides)).algo.pid
        assert (pid.kp, pid.ki, pid.kd, pid.ema_alpha, pid.derivative_delay) == (
            0.05, 0.0005, 0.1, 0.0, 1,
        )
        assert pid.penalty_max is None and not pid.ki_inside_integral
    cfg = validate(compose("algo=sac_lag", "pid=ema", "experiment=paper"))
    pid = cfg.algo.pid
    # The paper's gains; OmniSafe's pid_delta_p/d_ema_alpha 0.95 and pid_d_delay 10.
    assert (pid.kp, pid.ki, pid.kd, pid.ema_alpha, pid.derivative_delay) == (
        0.05, 0.0005, 0.1, 0.95, 10,
    )
    controller = build_lagrangian(cfg.algo, cfg.task.cost_limit)
    assert isinstance(controller, PIDLagrangian)
    assert (controller.error_ema, controller.cost_ema, controller.derivative_delay) == (
        0.95, 0.95, 10,
    )
    # First update from J = 900, d = 10: 0.05 (0.05 * 890) + 0.0005 * 890 + 0.1 * (0.95 * 10
    # + 0.05 * 900 - 10) = 7.12 (FSRL's form: 133.945).
    assert controller.update(900.0).item() == pytest.approx(7.12, abs=1e-9)
    # The command line still wins over the option.
    assert validate(compose("pid=ema", "algo.pid.ema_alpha=0.8")).algo.pid.ema_alpha == 0.8
    with pytest.raises(ConfigCompositionException) as err:
        compose("pid=lqr")
    assert "ema" in str(err.value) and "fsrl" in str(err.value)


def test_pid_omnisafe_is_sacpid_per_gradient_step(compose):
    # OmniSafe's SACPID.yaml: pid_kp 1e-6, pid_ki 1e-7, pid_kd 1e-7, pid_d_delay 10, both EMAs
    # 0.95; pid_lagrange.py: ki inside the integral, cost history from 0, sum_norm (no cap).
    from s3rl_torchrl.algorithms import build_lagrangian

    cfg = validate(compose("algo=sac_lag", "pid=omnisafe", "algo.lagrangian=pid",
                           "algo.lagrangian_cadence=step"))
    pid = cfg.algo.pid
    assert (pid.kp, pid.ki, pid.kd, pid.ema_alpha, pid.derivative_delay) == (
        1e-6, 1e-7, 1e-7, 0.95, 10,
    )
    assert pid.ki_inside_integral and pid.penalty_max is None
    controller = build_lagrangian(cfg.algo, 25.0)
    # OmniSafe's pid_update from J = 125, d = 25, written out: delta 100; I = 1e-7 * 100;
    # delta_p = 0.05 * 100; cost_d = 0.05 * 125; D = max(0, cost_d - 0) (history from 0).
    expected = 1e-6 * 0.05 * 100 + 1e-7 * 100 + 1e-7 * 0.05 * 125
    assert controller.update(125.0).item() == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(
    "override, message",
    [
        ("algo.update_per_step=-1", "'algo.update_per_step'"),
        ("algo.lagrangian=lqr", "allowed values are pid, learned, none"),
        ("collector.batching=threads", "allowed values are sync_vector"),
        ("algo.gamma=1.5", "must be in [0.0, 1.0]"),
        ("logger.backend=neptune", "allowed values are csv, tensorboard, wandb, mlflow, none"),
        ("network.activation=gelu", "allowed values are relu, tanh, elu, silu"),
        ("collector.frames_per_epoch=150", "multiple of collector.frames_per_batch"),
        ("algo.contrastive_cfg.temperature=0", "'algo.contrastive_cfg.temperature'"),
        # NaN passes every range comparison: each float field is checked for it on its own.
        ("task.cost_limit=nan", "Invalid value nan for 'task.cost_limit': must be a finite"),
        ("algo.pid.kd=inf", "Invalid value inf for 'algo.pid.kd': must be a finite number"),
        ("network.log_std_max=nan", "'network.log_std_max': must be a finite number"),
        ("algo.contrastive_cfg.lr=nan", "'algo.contrastive_cfg.lr': must be a finite number"),
        ("algo.lagrangian_cadence=epoch", "'algo.lagrangian_cadence': allowed values are collect"),
        ("algo.lagrangian_window=0", "'algo.lagrangian_window': must be in [1"),
        ("algo.lagrangian_target=0", "'algo.lagrangian_target': must be in (0.0, 1.0]"),
        ("algo.lagrangian_target=1.2", "'algo.lagrangian_target': must be in (0.0, 1.0]"),
        ("algo.lagrangian_eval_window=-1", "'algo.lagrangian_eval_window': must be in [0"),
        ("algo.contrastive_cfg.phase_at=middle",
         "'algo.contrastive_cfg.phase_at': allowed values are start, end"),
    ],
)
def test_bad_values_name_the_field_and_the_valid_choices(override, message, compose):
    with pytest.raises(ConfigError) as err:
        validate(compose(override))
    assert message in str(err.value)


def test_bad_types_and_unknown_keys_fail_at_composition(compose):
    with pytest.raises(ConfigCompositionException) as err:
        compose("algo.batch_size=big")
    assert "algo.batch_size" in str(err.value.__cause__) or "batch_size" in str(err.value)
    with pytest.raises(ConfigCompositionException):
        compose("algo.not_a_field=1")
    with pytest.raises(ConfigCompositionException) as err:
        compose("algo=trpo_lag")
    assert "s3rl" in str(err.value) and "sac_lag" in str(err.value)  # lists the options
    with pytest.raises(ConfigCompositionException):
        compose("task=SafetyCheetahVelocity-v1")


def test_python_dataclass_is_validated_too():
    cfg = TrainConfig()
    cfg.task.name = "SafetyHopperVelocity-v1"
    cfg.algo.batch_size = 0
    with pytest.raises(ConfigError, match="algo.batch_size"):
        validate(cfg)


def test_yaml_types_are_checked_against_the_schema(compose):
    with pytest.raises((ConfigCompositionException, ValidationError)):
        compose("collector.num_envs=1.5")


def test_experiment_overrides_the_primary_config(compose):
    # The experiment comes after _self_ in the defaults list: its values win over train.yaml's.
    cfg = validate(compose("experiment=tiny"))
    assert cfg.threads == 1 and cfg.save_interval == 1
    assert validate(compose("experiment=paper")).save_interval == 4
    # ... and the command line wins over both.
    assert validate(compose("experiment=tiny", "threads=2")).threads == 2


def test_compile_without_a_cpp_compiler_fails_before_training(compose):
    from torch._inductor import config as inductor_config

    cfg = compose("compile=true")
    validate(cfg)  # this machine has g++
    with inductor_config.patch({"cpp.cxx": (None, "no-such-c++-compiler")}):
        with pytest.raises(ConfigError) as err:
            validate(cfg)
        validate(compose("compile=false"))  # the way out the message names
    message = str(err.value)
    assert "'compile'" in message and "no-such-c++-compiler" in message
    assert "compile=false" in message and "g++" in message


# Gradient steps by hand (the loop's rule: update_per_step per frame of each batch ending at or
# after init_random_frames with >= batch_size stored transitions; n-step holds back n_step
# frames per env copy):
# - quick, 4000 frames: batches end at 1000..4000 < 5000 -> 0.
# - quick, 5000 frames: only the batch ending at 5000; 4 envs x (1250 - 2) = 4992 stored -> 500.
# - tiny (600 frames): batches ending at 200..600 (5); at 200 stored 2 x (100 - 2) = 196 >= 32
#   -> 5 x 100 x 0.25 = 125.
# - tiny with batch_size 400: stored 2 x (50 k - 2) = 196, 296, 396, 496, 596 after the batches
#   ending at 200..600 -> only the batches ending at 500 and 600 learn -> 50.
# - tiny, 200 frames, batch_size 200: stored 196 < 200 at the only eligible batch -> 0.
@pytest.mark.parametrize(
    "overrides, steps",
    [
        (("experiment=quick", "collector.total_frames=4000"), 0),
        (("experiment=quick", "collector.total_frames=5000"), 500),
        (("experiment=tiny",), 125),
        (("experiment=tiny", "algo.batch_size=400"), 50),
        (("experiment=tiny", "collector.total_frames=200", "algo.batch_size=200"), 0),
    ],
)
def test_planned_gradient_steps_by_hand(overrides, steps, compose):
    from omegaconf import OmegaConf

    cfg = OmegaConf.to_object(compose(*overrides))  # not validated: some cannot learn
    assert schedule_of(cfg).planned_gradient_steps() == steps


def _batch_frames(frames: int) -> tuple[str, str]:
    return f"collector.frames_per_batch={frames}", f"collector.frames_per_epoch={frames}"


# The on-policy schedule by hand: each batch of F frames owes ppo_epochs x ceil(F / batch_size)
# minibatch steps, from the first batch (no warm-up, init_random_frames is not used).
# - tiny: 6 batches of 100 frames, batch 32: 6 x 4 x ceil(100 / 32) = 6 x 4 x 4 = 96.
# - tiny, batch_size 100: 6 x 4 x 1 = 24.
# - quick: 40 batches of 1000 frames, batch 256: 40 x 4 x 4 = 640.
# - tiny, 200 frames with a 200-frame warm-up and batch_size 200 (off-policy: 0 steps):
#   2 x 4 x 1 = 8; ppo_epochs 10: 2 x 10 x 1 = 20.
# - tiny, frames_per_batch 101 over 2 envs: torchrl collects 102 frames a batch, 6 batches for
#   600 frames: 6 x 4 x ceil(102 / 32) = 6 x 4 x 4 = 96; frames_per_batch 130 (130 a batch,
#   5 batches): 5 x 4 x 5 = 100.
@pytest.mark.parametrize(
    "overrides, steps",
    [
        (("experiment=tiny",), 96),
        (("experiment=tiny", "algo.batch_size=100"), 24),
        (("experiment=quick",), 640),
        (("experiment=tiny", "collector.total_frames=200", "algo.batch_size=200"), 8),
        (
            (
                "experiment=tiny",
                "collector.total_frames=200",
                "algo.batch_size=200",
                "algo.ppo_epochs=10",
            ),
            20,
        ),
        (("experiment=tiny", *_batch_frames(101)), 96),
        (("experiment=tiny", *_batch_frames(130)), 100),
    ],
)
def test_planned_on_policy_gradient_steps_by_hand(overrides, steps, compose):
    cfg = validate(compose("algo=ppo_lag", "compile=false", *overrides))
    assert schedule_of(cfg).planned_gradient_steps() == steps
    assert schedule_of(cfg).warmup_frames() == 0


def test_a_run_that_cannot_learn_is_refused(compose):
    # The new user's run: 4000 frames of the quick experiment are all random warm-up.
    with pytest.raises(ConfigError) as err:
        validate(compose("experiment=quick", "collector.total_frames=4000", "compile=false"))
    message = str(err.value)
    assert "'collector.total_frames'" in message and "no gradient step" in message
    assert "init_random_frames (5000)" in message and "algo.batch_size (256)" in message
    # ... and what would work, each checked to learn: 5000 frames, or a 4000-frame warm-up.
    assert "total_frames to 5000 or more" in message
    assert "init_random_frames to 4000 or less" in message
    for fix in ("collector.total_frames=5000", "collector.init_random_frames=4000"):
        validate(compose("experiment=quick", "collector.total_frames=4000", fix, "compile=false"))
    # total_frames == init_random_frames still learns on the last batch (not refused).
    validate(compose("experiment=tiny", "collector.total_frames=200"))
    # Too few stored transitions for one batch is refused as well.
    with pytest.raises(ConfigError, match="no gradient step"):
        validate(compose("experiment=tiny", "collector.total_frames=200", "algo.batch_size=200"))


def test_safe_preset_reads_its_table_of_task_values(compose):
    # experiment=safe takes a task's own values (trainer/presets.py) where its table has them,
    # its defaults elsewhere; a command-line value still wins.
    from s3rl_torchrl.trainer.presets import safe_task_settings

    goal = validate(compose("experiment=safe", "task=SafetyPointGoal1-v0"))
    own = safe_task_settings("SafetyPointGoal1-v0")
    assert goal.algo.lagrangian_lr == own.lagrangian_lr == 3e-6
    assert goal.algo.lagrangian_warmup_frames == own.lagrangian_warmup_frames == 100_000
    assert goal.task.cost_limit == own.cost_limit == 25.0
    ball = validate(compose("experiment=safe", "task=SafetyBallRun-v0"))
    assert ball.algo.lagrangian_lr == 3e-4 and ball.task.cost_limit == 10.0
    assert ball.algo.lagrangian_warmup_frames == ball.collector.init_random_frames == 2000
    mine = validate(compose("experiment=safe", "task=SafetyPointGoal1-v0",
                            "algo.lagrangian_lr=1e-5", "task.cost_limit=10"))
    assert mine.algo.lagrangian_lr == 1e-5 and mine.task.cost_limit == 10.0
    paper = validate(compose("experiment=paper", "task=SafetyPointGoal1-v0"))
    assert paper.task.cost_limit == 10.0 and paper.algo.lagrangian_warmup_frames == 0


def test_sound_critics_read_the_cost_pair_as_the_presets_table_says(compose):
    from s3rl_torchrl.trainer.presets import safe_task_settings

    hopper = "SafetyHopperVelocity-v1"
    assert safe_task_settings(hopper).cost_critic_read == "mean"
    for algo in ("sac_lag", "s3rl"):
        cfg = validate(compose("experiment=safe", f"task={hopper}", f"algo={algo}"))
        assert cfg.algo.cost_critic_read == "mean" and cfg.algo.cost_nonnegative
    # The paper's id of the same task shares the entry; the v5 robot, a different task, does not.
    paper_id = validate(compose("experiment=safe", "task=SafetyHopperVelocityGymnasium-v1"))
    assert paper_id.algo.cost_critic_read == "mean"
    v5 = validate(compose("experiment=safe", "task=SafetyHopperVelocityMujocoV5-v1"))
    assert v5.algo.cost_critic_read == "max"
    # Elsewhere the sound read is the max; FSRL's critics and the command line still win.
    cheetah = validate(compose("experiment=safe", "task=SafetyHalfCheetahVelocity-v1"))
    assert cheetah.algo.cost_critic_read == "max"
    fsrl = validate(compose("experiment=safe", f"task={hopper}", "critic=fsrl"))
    assert fsrl.algo.cost_critic_read == "min"
    mine = validate(compose("experiment=safe", f"task={hopper}", "algo.cost_critic_read=max"))
    assert mine.algo.cost_critic_read == "max"


def test_safe_preset_has_the_sound_critics_and_paper_fsrls(compose):
    safe = validate(compose("experiment=safe", "algo=sac_lag"))
    assert (safe.algo.cost_critic_read, safe.algo.cost_nonnegative) == ("max", True)
    assert (safe.algo.cost_entropy, safe.algo.entropy_rescaling) == (False, False)
    s3rl = validate(compose("experiment=safe", "algo=s3rl"))
    assert s3rl.algo.cost_critic_read == "max" and not s3rl.algo.entropy_rescaling
    # Still a choice: critic=fsrl on the command line gives FSRL's under the safe schedule.
    fsrl = validate(compose("experiment=safe", "algo=sac_lag", "critic=fsrl"))
    assert (fsrl.algo.cost_critic_read, fsrl.algo.entropy_rescaling) == ("min", True)
    assert fsrl.algo.lagrangian_cadence == safe.algo.lagrangian_cadence == "step"
    paper = validate(compose("experiment=paper", "algo=sac_lag"))
    assert (paper.algo.cost_critic_read, paper.algo.cost_nonnegative) == ("min", False)


@pytest.mark.parametrize(
    "phase_at, interval, expected",
    [
        # One phase per T = 10 gradient steps of the first 45, from the first full interval on.
        ("start", 10, [11, 21, 31, 41]),
        ("end", 10, [10, 20, 30, 40]),
        # T = 1: after every step either way.
        ("start", 1, list(range(1, 46))),
        ("end", 1, list(range(1, 46))),
    ],
)
def test_contrastive_phase_runs_at_the_start_or_the_end_of_each_interval(
    phase_at, interval, expected
):
    from s3rl_torchrl.algorithms.config import ContrastiveConfig

    cfg = ContrastiveConfig(update_interval=interval, phase_at=phase_at)
    assert [step for step in range(1, 46) if cfg.phase_due(step)] == expected
