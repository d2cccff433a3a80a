"""Figure 4's panels: stored and read back exactly (up to the CSV's 6 significant digits)."""

from __future__ import annotations

import json
import math

import numpy as np

from s3rl_torchrl.diagnostics.probe import ProbeResult
from s3rl_torchrl.report.embeddings import EmbeddingPanel, load_panel, save_panel, tsne_2d


def test_panel_round_trip_keeps_an_unfitted_probe_as_nan(tmp_path):
    rng = np.random.default_rng(0)
    xy = rng.normal(size=(7, 2)) * 1000
    safe = np.array([1, 0, 1, 1, 0, 1, 1], dtype=bool)
    nan = float("nan")
    panel = EmbeddingPanel(xy, safe, ProbeResult(nan, nan, nan, 0, 0, 5, 2), episodes=3)
    save_panel(panel, tmp_path)
    # Valid JSON (no NaN literal): the undefined scores are null.
    saved = json.loads((tmp_path / "figure4_probe.json").read_text(), parse_constant=None)
    assert saved == {"episodes": 3, "probe": {"accuracy": None, "auc": None, "chance": None,
                                              "n_train": 0, "n_test": 0, "n_safe": 5,
                                              "n_unsafe": 2}}
    back = load_panel(tmp_path)
    np.testing.assert_allclose(back.xy, xy, rtol=1e-5)
    np.testing.assert_array_equal(back.safe, safe)
    assert math.isnan(back.probe.accuracy) and not back.probe.fitted
    assert (back.probe.n_safe, back.probe.n_unsafe, back.episodes) == (5, 2, 3)
    assert load_panel(tmp_path / "elsewhere") is None


def test_tsne_keeps_at_most_max_states_in_order_and_their_labels():
    rng = np.random.default_rng(1)
    z = np.concatenate([rng.normal(0, 1, (40, 8)), rng.normal(6, 1, (40, 8))])
    safe = np.arange(80) < 40
    xy, kept = tsne_2d(z, safe, max_states=50, seed=0)
    assert xy.shape == (50, 2) and kept.sum() + (~kept).sum() == 50
    # The two well-separated clusters stay apart: every state is nearer its own class's centre.
    centres = [xy[kept].mean(0), xy[~kept].mean(0)]
    own = np.where(kept, 0, 1)
    dist = np.stack([np.linalg.norm(xy - c, axis=1) for c in centres], axis=1)
    assert (dist.argmin(1) == own).all()
