"""torchrl's ``Collector`` with a carrier a checkpoint can keep and give back.

Between two batches a ``Collector`` holds its *carrier*: the tensordict each env copy's next
step starts from (the last observation, the running episode sums and step counts, ...). A
resumed run that built a new collector would reset every env instead and start new episodes;
with the carrier (and the envs' own state, :mod:`s3rl_torchrl.envs.state`) restored, it goes on
with the same episodes as the run that was interrupted.
"""

from __future__ import annotations

from tensordict import TensorDictBase
from torchrl.collectors import Collector

__all__ = ["ResumableCollector"]


class ResumableCollector(Collector):
    """A ``Collector`` whose :attr:`carrier` can be read (for a checkpoint) and replaced (on
    resume, after the envs' state was restored). Everything else is torchrl's."""

    @property
    def carrier(self) -> TensorDictBase:
        """Where the next batch starts: each copy's current observation and running entries."""
        return self._carrier

    def load_carrier(self, carrier: TensorDictBase) -> None:
        """Start the next batch from ``carrier`` (a copy of :attr:`carrier` from a checkpoint)
        instead of the reset the collector made when it was built. Restore the envs' own
        state (:func:`s3rl_torchrl.envs.state.restore_env`) too, or the two disagree."""
        current = self._carrier
        missing = set(current.keys(True, True)) - set(carrier.keys(True, True))
        if carrier.batch_size != current.batch_size or missing:
            raise ValueError(
                f"the saved carrier (batch {tuple(carrier.batch_size)}) does not fit this "
                f"collector's (batch {tuple(current.batch_size)}; missing {sorted(map(str, missing))})"
            )
        current.update(carrier.select(*current.keys(True, True)))
