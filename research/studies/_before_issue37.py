"""The one patch that the studies of the code before issue 37 (commit 8e0ee0c, which still had
``SACLagLoss(critic_eval=...)``) make to it: ``compare_refactor.py``'s reference runs and
``critic_eval_stacked.py``.

That version's ``StackedSACLag`` could run the ``"vmap"`` critic evaluation only once its
template loss gave each per-agent parameter tensordict its batch size back inside the ``vmap``
over agents, as the later version does; :func:`give_template_batch_sizes` patches that in. It
changes no number.
"""

from __future__ import annotations

from types import ModuleType


def stacked_module() -> ModuleType:
    """``StackedSACLag``'s module: ``s3rl_torchrl.objectives.stacked`` up to 8e0ee0c,
    ``s3rl_torchrl.algorithms.stacked`` after it."""
    try:
        from s3rl_torchrl.objectives import stacked
    except ImportError:
        from s3rl_torchrl.algorithms import stacked
    return stacked


def give_template_batch_sizes(stacked: ModuleType) -> None:
    """Make ``stacked._template_loss`` return a template whose per-agent tensordicts (and their
    detached caches) keep the agent's batch size inside ``vmap``."""
    template_loss = stacked._template_loss

    def patched(loss):
        template = template_loss(loss)
        cls = type(template)
        for name in stacked.PER_AGENT:
            size = getattr(getattr(loss, name, None), "batch_size", None)
            if size is None:
                continue
            cached = "_cached_detached_" + name.replace("_network_params", "_params")
            for attribute, detach in ((name, False), (cached, True)):
                if detach and not hasattr(cls, attribute):
                    continue

                def read(self, name=name, size=size, detach=detach):
                    params = self._current.params.get(name)
                    params = params.detach() if detach else params
                    params.batch_size = size
                    return params

                setattr(cls, attribute, property(read))
        return template

    stacked._template_loss = patched
