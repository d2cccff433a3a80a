"""Policy-encoder embeddings of the states a checkpoint visits in evaluation (Figure 4).

A checkpoint's Figure-4 panel (:class:`EmbeddingPanel`) is small once computed: the t-SNE
coordinates of at most ``tsne_states`` states, their labels and the linear probe's scores.
``s3rl-report RUNS --export-runs DEST`` stores it beside the exported run
(:func:`save_panel`: ``figure4_states.csv``, ``figure4_probe.json``), so that Figure 4 is
rebuilt from a results tree without the checkpoints, which are not kept.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from s3rl_torchrl.diagnostics.probe import ProbeResult, linear_probe
from s3rl_torchrl.envs import get_task, make_env
from s3rl_torchrl.modules import get_policy_encoder
from s3rl_torchrl.report.runs import FIGURE4_FILES
from s3rl_torchrl.trainer.evaluate_checkpoint import load_policy

__all__ = [
    "RolloutEmbeddings",
    "rollout_embeddings",
    "EmbeddingPanel",
    "embedding_panel",
    "tsne_2d",
    "save_panel",
    "load_panel",
    "PANEL_FILES",
]

PANEL_FILES = FIGURE4_FILES
PANEL_STATES_FILE, PANEL_PROBE_FILE = PANEL_FILES


@dataclass
class RolloutEmbeddings:
    embeddings: np.ndarray  # [N, d] policy-encoder outputs z = f(s_t)
    safe: np.ndarray  # [N] bool: cost_t == 0 (the label of s_t, as in the replay buffer)
    cost: np.ndarray  # [N] cost_t


def rollout_embeddings(
    checkpoint: str | Path, episodes: int = 2, max_steps: int | None = None, seed: int = 0
) -> RolloutEmbeddings:
    """Roll a checkpoint's policy out deterministically and embed every visited state.

    ``episodes`` env copies run ``max_steps`` steps each (None: the task's episode length) on
    fresh test envs (an episode that ends early is reset and continues, so every copy gives
    ``max_steps`` states). Each state
    ``s_t`` is labelled safe when the step taken from it costs nothing (``CostLabel``).
    """
    actor, cfg = load_policy(checkpoint)
    if max_steps is None:
        max_steps = get_task(cfg.task.name).max_episode_steps
    encoder = get_policy_encoder(actor)
    env = make_env(cfg.task.name, num_envs=episodes, seed=seed)
    try:
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            rollout = env.rollout(max_steps, actor, break_when_any_done=False)
            states = rollout.reshape(-1)
            z = encoder(states.select(*encoder.in_keys).clone()).get(encoder.out_keys[0])
    finally:
        env.close()
    return RolloutEmbeddings(
        embeddings=z.cpu().numpy(),
        safe=states["next", "safe"].reshape(-1).cpu().numpy(),
        cost=states["next", "cost"].sum(-1).reshape(-1).cpu().numpy(),
    )


def tsne_2d(
    embeddings: np.ndarray, safe: np.ndarray, max_states: int = 1000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """t-SNE (scikit-learn) of at most ``max_states`` of the embeddings, drawn with a seeded
    generator (kept in their original order). Returns ``(xy [n, 2], safe [n])``."""
    from sklearn.manifold import TSNE
    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(seed)
    keep = np.sort(rng.permutation(len(embeddings))[:max_states])
    z, safe = np.asarray(embeddings)[keep], np.asarray(safe)[keep].astype(bool)
    perplexity = float(min(30.0, max(2.0, (len(z) - 1) / 3)))
    # One OpenMP thread: measured 2.5x faster than the default on 2 busy cores.
    with threadpool_limits(limits=1):
        xy = TSNE(n_components=2, perplexity=perplexity, init="pca",
                  random_state=seed).fit_transform(z.astype(np.float64))
    return xy, safe


@dataclass
class EmbeddingPanel:
    """What Figure 4 shows of one checkpoint."""

    xy: np.ndarray  # [n, 2] t-SNE coordinates of at most tsne_states rollout states
    safe: np.ndarray  # [n] their labels
    probe: ProbeResult  # the linear probe on ALL the rollout states' embeddings
    episodes: int  # evaluation env copies rolled out


def embedding_panel(
    checkpoint: str | Path,
    episodes: int = 2,
    max_steps: int | None = None,
    tsne_states: int = 1000,
    seed: int = 0,
) -> EmbeddingPanel:
    """Roll ``checkpoint`` out (:func:`rollout_embeddings`), probe every state's embedding and
    t-SNE at most ``tsne_states`` of them."""
    data = rollout_embeddings(checkpoint, episodes=episodes, max_steps=max_steps)
    probe = linear_probe(data.embeddings, data.safe, seed=seed)
    xy, safe = tsne_2d(data.embeddings, data.safe, tsne_states, seed)
    return EmbeddingPanel(xy, safe, probe, episodes)


def save_panel(panel: EmbeddingPanel, run_dir: str | Path) -> list[Path]:
    """Write ``panel`` beside a run: the states as CSV (x, y, safe), the probe as JSON."""
    run_dir = Path(run_dir)
    states, probe = run_dir / PANEL_STATES_FILE, run_dir / PANEL_PROBE_FILE
    with states.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["x", "y", "safe"])
        # 6 significant digits: far below what a scatter plot resolves, ~25 bytes per state.
        writer.writerows((f"{x:.6g}", f"{y:.6g}", int(s)) for (x, y), s in zip(
            panel.xy.tolist(), panel.safe.tolist(), strict=True))
    scores = {k: (None if isinstance(v, float) and math.isnan(v) else v)
              for k, v in asdict(panel.probe).items()}
    probe.write_text(json.dumps({"episodes": panel.episodes, "probe": scores}, indent=2) + "\n")
    return [states, probe]


def load_panel(run_dir: str | Path) -> EmbeddingPanel | None:
    """The panel :func:`save_panel` wrote in ``run_dir``; None when there is none."""
    run_dir = Path(run_dir)
    states, probe = run_dir / PANEL_STATES_FILE, run_dir / PANEL_PROBE_FILE
    if not (states.is_file() and probe.is_file()):
        return None
    with states.open(newline="") as f:
        rows = list(csv.DictReader(f))
    xy = np.array([[float(r["x"]), float(r["y"])] for r in rows]).reshape(-1, 2)
    safe = np.array([r["safe"] == "1" for r in rows], dtype=bool)
    saved = json.loads(probe.read_text())
    scores = {k: (math.nan if v is None else v) for k, v in saved["probe"].items()}
    return EmbeddingPanel(xy, safe, ProbeResult(**scores), int(saved["episodes"]))
