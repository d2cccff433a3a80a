"""The helpers the Lagrangian losses share, against the losses they serve."""

from __future__ import annotations

import pytest

from s3rl_torchrl.objectives import ddpg_lag, sac_lag
from tests.objectives import test_ddpg_lag, test_sac_lag


@pytest.mark.parametrize(
    "module, make_loss",
    [(sac_lag, test_sac_lag.make_loss), (ddpg_lag, test_ddpg_lag.make_loss)],
    ids=["sac_lag", "ddpg_lag"],
)
def test_forward_clears_every_parameter_container_the_loss_holds(module, make_loss):
    # convert_to_functional names what it registers; a compiled forward must clear the weak
    # references of each of those, the cost critics' included.
    loss = make_loss()[0]
    held = {name for name in loss._modules if name.endswith("_network_params")}
    assert len(held) >= 5
    assert held <= set(module._PARAMETER_CONTAINERS)
