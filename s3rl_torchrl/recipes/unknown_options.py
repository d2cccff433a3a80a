"""A command-line key the config does not have: which keys its node does have; an option a Hydra
plugin brings, while the plugin is not installed: which extra installs it.

Hydra refuses ``s3rl-train algo.actor_lrr=1e-3`` (or ``s3rl-eval eval.episodes=1``, the training
command's key) with "Could not override 'algo.actor_lrr'", a suggestion to append the key with
``+`` (which a structured config refuses too) and OmegaConf's "Key 'actor_lrr' not in
'SACConfig'": the problem, but not the valid choices. :func:`describe_unknown_option` turns
that error into one line naming the keys the node has and the closest one; the recipes print
it after Hydra's message (:func:`hint_unknown_option`), and a sweep's refused jobs carry it
(:mod:`s3rl_torchrl.recipes.launch_checks`). Without Hydra's Optuna sweeper, ``+search=...`` or
``hydra/sweeper=optuna`` stops on "Could not find 'hydra/sweeper/optuna'" (available: basic), which
does not say where the option comes from: :func:`describe_missing_plugin` names the package and
this package's extra.
"""

from __future__ import annotations

import difflib
import re
import sys
from collections.abc import Iterator
from contextlib import contextmanager

from hydra.errors import MissingConfigException
from omegaconf import DictConfig
from omegaconf.errors import ConfigAttributeError, ConfigKeyError

__all__ = ["PLUGIN_OPTIONS", "describe_missing_plugin", "describe_unknown_option",
           "hint_unknown_option"]

#: The Hydra options a plugin brings (configs/hydra/launcher/*.yaml build on the launchers'),
#: with the plugin's package and the extra of pyproject.toml that installs it.
PLUGIN_OPTIONS = {
    "hydra/sweeper/optuna": ("hydra-optuna-sweeper", "search"),
    "hydra/launcher/joblib": ("hydra-joblib-launcher", "sweep"),
    "hydra/launcher/submitit_slurm": ("hydra-submitit-launcher", "sweep"),
    "hydra/launcher/submitit_local": ("hydra-submitit-launcher", "sweep"),
}

_OVERRIDE = re.compile(r"To append to your config use \+(?P<line>\S.*)$", re.MULTILINE)


def _unknown_key_error(err: BaseException) -> ConfigKeyError | ConfigAttributeError | None:
    seen = err
    while seen is not None:
        if isinstance(seen, (ConfigKeyError, ConfigAttributeError)) and isinstance(
            getattr(seen, "parent_node", None), DictConfig
        ):
            return seen
        seen = seen.__cause__
    return None


def describe_unknown_option(err: BaseException, command: str) -> str | None:
    """For Hydra's refusal of an override whose key the config does not have: one line naming
    the key, the keys its node has, and the closest of them (or the override without the
    unknown part, when what follows it is a key there: ``eval.episodes=1`` -> ``episodes=1``).
    None for any other error."""
    cause = _unknown_key_error(err)
    if cause is None:
        return None
    unknown = str(cause.key)
    full_key = str(cause.full_key or unknown)
    node = full_key[: -len(unknown)].rstrip(".") if full_key.endswith(unknown) else ""
    keys = [str(k) for k in cause.parent_node.keys() if not (node == "" and k == "hydra")]
    match = _OVERRIDE.search(str(err))
    value = match.group("line").split("=", 1)[1] if match and "=" in match.group("line") else None
    given = match.group("line").split("=", 1)[0] if match else full_key
    where = f"{node} ({cause.object_type.__name__})" if node and cause.object_type else node
    line = f"unknown option '{given}': {where or command} has no '{unknown}'"
    line += f"; its options: {', '.join(keys)}."
    prefix = f"{node}." if node else ""
    rest = given[len(prefix) + len(unknown) :].lstrip(".")
    if rest and rest.split(".")[0] in keys:
        suggestions = [prefix + rest]  # a key of the other command's config (eval.episodes)
    else:
        # A key cut short (algo.alpha) may begin several (alpha_init, alpha_lr): name them all,
        # where difflib's one closest would choose for the user.
        close = [k for k in keys if k.startswith(unknown)] or difflib.get_close_matches(
            unknown, keys, n=1)
        suggestions = [prefix + k + (f".{rest}" if rest else "") for k in close]
    if suggestions:
        options = [s if value is None else f"{s}={value}" for s in suggestions]
        named = " or ".join(filter(None, [", ".join(options[:-1]), options[-1]]))
        line += f" Did you mean {named}?"
    return line


def describe_missing_plugin(err: BaseException) -> str | None:
    """For Hydra's refusal of an option that one of :data:`PLUGIN_OPTIONS`' plugins brings: one
    line naming the plugin and the command that installs it. None for any other error."""
    if not isinstance(err, MissingConfigException) or err.missing_cfg_file not in PLUGIN_OPTIONS:
        return None
    package, extra = PLUGIN_OPTIONS[err.missing_cfg_file]
    return (f"'{err.missing_cfg_file}' comes with Hydra's plugin {package}, which is not "
            f"installed: pip install 's3rl-torchrl[{extra}]' (in a checkout: pip install -e "
            f"'.[{extra}]'; `make setup` installs it).")


def _first_job_overrides(arguments: list[str]) -> list[str]:
    """The command's overrides with each sweep (``seed=1,2``) at its first value: one job."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    overrides = []
    for override in OverridesParser.create().parse_overrides(arguments):
        if override.is_sweep_override():
            first = next(iter(override.sweep_string_iterator()))
            overrides.append(f"{override.get_key_element()}={first}")
        else:
            overrides.append(override.input_line)
    return overrides


def _composition_error(config_name: str, arguments: list[str]) -> Exception | None:
    """What composing the command's config (its first job, for a sweep) raises, if anything."""
    from hydra import compose, initialize_config_dir
    from hydra._internal.utils import get_args_parser
    from hydra.core.global_hydra import GlobalHydra

    from s3rl_torchrl.recipes import config_dir

    try:
        args = get_args_parser().parse_args(arguments)
        overrides = _first_job_overrides(args.overrides)
    except (Exception, SystemExit):  # not a command Hydra itself would have parsed
        return None
    if args.config_dir or args.config_path:  # configs of the user's: composed here they differ
        return None
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            compose(config_name=args.config_name or config_name, overrides=overrides)
    except Exception as err:
        return err
    finally:
        GlobalHydra.instance().clear()
    return None


@contextmanager
def hint_unknown_option(command: str, config_name: str) -> Iterator[None]:
    """Around a recipe's Hydra main: when Hydra stops (status 1) on a key the config does not
    have, or an option of a plugin not installed, print after its message the line of
    :func:`describe_unknown_option` or :func:`describe_missing_plugin`. Hydra prints
    and exits before the exception could be read, so the command's config is composed once
    more, only then."""
    try:
        yield
    except SystemExit as stop:
        if stop.code == 1:
            err = _composition_error(config_name, sys.argv[1:])
            hint = None
            if err is not None:
                hint = describe_unknown_option(err, command) or describe_missing_plugin(err)
            if hint is not None:
                print(f"{command}: {hint}", file=sys.stderr)
        raise
