"""The algorithm registry: ``algo=<name>`` -> its family and its defaults.

A new algorithm of an existing family is one entry here and one YAML in ``configs/algo/``
(whose defaults list picks this entry's config, ``/algo_defaults@_here_: <name>``); a new
family is a module that ends with its :class:`~s3rl_torchrl.algorithms.agent.Family`.
"""

from __future__ import annotations

from dataclasses import dataclass

from s3rl_torchrl.algorithms.agent import Family
from s3rl_torchrl.algorithms.config import AlgoConfig, ConfigError
from s3rl_torchrl.algorithms.ddpg import DDPG
from s3rl_torchrl.algorithms.ppo import PPO
from s3rl_torchrl.algorithms.sac import SAC

__all__ = ["ALGORITHMS", "FAMILIES", "Algorithm", "family_of"]


@dataclass(frozen=True)
class Algorithm:
    """One algorithm: its family, its Lagrangian controller (``"none"``: unconstrained, lambda
    stays 0 and no cost critic is built) and whether it runs S3RL's contrastive phase."""

    family: Family
    lagrangian: str
    contrastive: bool

    def config(self, name: str) -> AlgoConfig:
        """The algorithm's config: its family's defaults with this entry's values."""
        return self.family.config(
            name=name, lagrangian=self.lagrangian, contrastive=self.contrastive
        )


ALGORITHMS: dict[str, Algorithm] = {
    "s3rl": Algorithm(SAC, "pid", contrastive=True),  # the paper's method
    "sac_lag": Algorithm(SAC, "pid", contrastive=False),  # FSRL's SAC-Lag, the paper's baseline
    "sac": Algorithm(SAC, "none", contrastive=False),
    "s3rl_nolag": Algorithm(SAC, "none", contrastive=True),  # the paper's unconstrained S3RL
    "ddpg_lag": Algorithm(DDPG, "pid", contrastive=False),  # FSRL's DDPG-Lag
    "ddpg": Algorithm(DDPG, "none", contrastive=False),
    "s3rl_ddpg_lag": Algorithm(DDPG, "pid", contrastive=True),
    "ppo_lag": Algorithm(PPO, "pid", contrastive=False),  # FSRL's PPO-Lag (on-policy)
    "ppo": Algorithm(PPO, "none", contrastive=False),
    "s3rl_ppo_lag": Algorithm(PPO, "pid", contrastive=True),
}
FAMILIES: dict[str, Family] = {family.name: family for family in (SAC, DDPG, PPO)}


def family_of(algo: AlgoConfig | str) -> Family:
    """The family of an algorithm (its config or its name)."""
    name = algo if isinstance(algo, str) else algo.name
    if name not in ALGORITHMS:
        raise ConfigError(
            f"Invalid value {name!r} for 'algo.name': allowed values are "
            + ", ".join(ALGORITHMS)
            + "."
        )
    return ALGORITHMS[name].family
