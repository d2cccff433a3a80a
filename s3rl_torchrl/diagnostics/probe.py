"""Linear probe: how well a logistic regression reads the safe label off an embedding.

S3RL's claim (paper, Sections 3-4 and Figure 4) is that the contrastive phase makes the policy
encoder's embeddings separate safe from unsafe states. The probe puts a number on it: fit a
logistic regression (scikit-learn) on part of the (embedding, label) pairs and report the
accuracy and ROC AUC on the held-out rest. Chance is the majority-class rate for the accuracy
and 0.5 for the AUC.

Used by ``s3rl-report`` (embeddings of evaluation rollouts, Figure 4) and by the trainer (a
``probe/accuracy`` and ``probe/auc`` column per epoch, on a class-balanced sample of the replay
buffer: :func:`replay_probe`).

The graded form (:func:`graded_probe`, :func:`replay_graded_probe`) asks the same of a graded
safety label (the cost-to-go or a task's margin, docs/representation.md): fit a linear
regression from the embedding to the label and report, on the held-out rest, its R^2 and the
Spearman rank correlation between prediction and label (chance: R^2 <= 0, Spearman 0). The
trainer logs ``probe/spearman`` and ``probe/r2`` per epoch when the contrastive phase uses a
graded label.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

__all__ = [
    "GradedProbeResult",
    "ProbeResult",
    "graded_probe",
    "linear_probe",
    "replay_graded_probe",
    "replay_probe",
    "MIN_PER_CLASS",
    "MIN_GRADED",
]

#: Fewer examples of a class than this (in the whole set) and the probe is not fitted (NaN).
MIN_PER_CLASS = 5
#: Fewer examples than this (or a constant label) and the graded probe is not fitted (NaN).
MIN_GRADED = 10


@dataclass(frozen=True)
class ProbeResult:
    """Held-out scores of the probe; NaN when a class is (nearly) absent."""

    accuracy: float
    auc: float
    chance: float  # accuracy of always predicting the held-out majority class
    n_train: int
    n_test: int
    n_safe: int
    n_unsafe: int

    @property
    def fitted(self) -> bool:
        return not math.isnan(self.accuracy)


def linear_probe(
    embeddings: np.ndarray | torch.Tensor,
    safe: np.ndarray | torch.Tensor,
    test_fraction: float = 0.3,
    seed: int = 0,
) -> ProbeResult:
    """Fit ``safe ~ logistic(standardised embedding)`` and score it on a held-out split.

    The split is stratified (both classes in train and test) and seeded, the fit deterministic
    (lbfgs), so equal inputs give equal scores. Neither the global numpy nor torch RNG is used.

    Args:
        embeddings: ``[N, d]`` features.
        safe: ``[N]`` booleans (``True`` = safe).
        test_fraction: share of the examples held out for scoring.
        seed: seed of the split.
    """
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import accuracy_score, roc_auc_score
    from sklearn.model_selection import train_test_split
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    from threadpoolctl import threadpool_limits

    x = _numpy(embeddings).astype(np.float64).reshape(len(embeddings), -1)
    y = _numpy(safe).astype(bool).reshape(-1)
    if len(x) != len(y):
        raise ValueError(f"embeddings ({len(x)}) and labels ({len(y)}) differ in length.")
    n_safe, n_unsafe = int(y.sum()), int((~y).sum())
    if min(n_safe, n_unsafe) < MIN_PER_CLASS:
        nan = float("nan")
        return ProbeResult(nan, nan, nan, 0, 0, n_safe, n_unsafe)
    x_train, x_test, y_train, y_test = train_test_split(
        x, y, test_size=test_fraction, stratify=y, random_state=seed
    )
    model = make_pipeline(StandardScaler(), LogisticRegression(max_iter=1000))
    # One BLAS thread: a fit of a few thousand rows gains nothing from more, and the trainer
    # shares small machines (the same reason it runs torch on one thread).
    with threadpool_limits(limits=1):
        model.fit(x_train, y_train)
        score = model.predict_proba(x_test)[:, 1]
    majority = max(y_test.mean(), 1.0 - y_test.mean())
    return ProbeResult(
        accuracy=float(accuracy_score(y_test, score >= 0.5)),
        auc=float(roc_auc_score(y_test, score)),
        chance=float(majority),
        n_train=len(y_train),
        n_test=len(y_test),
        n_safe=n_safe,
        n_unsafe=n_unsafe,
    )


def replay_probe(
    replay_buffer,
    encoder,
    seed: int,
    per_class: int = 1000,
    label_key=("next", "safe"),
) -> ProbeResult:
    """The probe on a class-balanced sample of a replay buffer's transitions.

    Up to ``per_class`` safe and ``per_class`` unsafe transitions are drawn without replacement
    with a ``torch.Generator`` seeded by ``seed``: the global RNGs are left untouched, so
    training goes exactly as it would without the probe. The label ``("next", "safe")`` is
    ``cost_t == 0`` and describes ``s_t``, the transition's root ``"observation"``
    (:class:`~s3rl_torchrl.transforms.CostLabel`), which ``encoder`` embeds. Balanced classes
    make the accuracy comparable across runs whatever their share of unsafe steps (chance 0.5).

    ``encoder`` is a TensorDictModule (the actor's :class:`~s3rl_torchrl.modules.PolicyEncoder`,
    ``get_policy_encoder(actor)``); its first out key is the embedding.
    """
    storage = replay_buffer.storage
    size = len(storage)
    if size == 0:
        return linear_probe(np.zeros((0, 1)), np.zeros(0, dtype=bool))
    stored = storage[:size]  # a view on the first `size` slots (the filled ones)
    labels = stored.get(label_key).reshape(size, -1)[:, 0].bool().cpu()
    generator = torch.Generator().manual_seed(int(seed))
    picked = []
    for mask in (labels, ~labels):
        index = mask.nonzero().squeeze(-1)
        order = torch.randperm(len(index), generator=generator)[:per_class]
        picked.append(index[order])
    index = torch.cat(picked)
    device = next(encoder.parameters()).device  # the buffer may live elsewhere
    with torch.no_grad():
        states = stored[index].select(*encoder.in_keys).to(device)
        embeddings = encoder(states).get(encoder.out_keys[0])
    return linear_probe(embeddings, labels[index], seed=int(seed) % 2**32)


def _numpy(x) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x)


@dataclass(frozen=True)
class GradedProbeResult:
    """Held-out scores of the graded probe; NaN when it could not be fitted."""

    spearman: float  # rank correlation of the held-out predictions with the label
    r2: float  # coefficient of determination of the held-out predictions
    n_train: int
    n_test: int

    @property
    def fitted(self) -> bool:
        return not math.isnan(self.r2)


def graded_probe(
    embeddings: np.ndarray | torch.Tensor,
    label: np.ndarray | torch.Tensor,
    test_fraction: float = 0.3,
    seed: int = 0,
) -> GradedProbeResult:
    """Fit ``label ~ linear(standardised embedding)`` (least squares) and score it held out.

    The split is seeded (a random permutation, not stratified: the label is continuous), the
    fit exact, so equal inputs give equal scores; neither the global numpy nor torch RNG is
    used. NaN when there are fewer than :data:`MIN_GRADED` examples or the label is constant in
    the training or the test part (no ranking to recover).

    Args:
        embeddings: ``[N, d]`` features.
        label: ``[N]`` graded labels (finite floats).
        test_fraction: share of the examples held out for scoring.
        seed: seed of the split.
    """
    from scipy.stats import spearmanr
    from sklearn.linear_model import LinearRegression
    from sklearn.metrics import r2_score
    from sklearn.model_selection import train_test_split
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    from threadpoolctl import threadpool_limits

    x = _numpy(embeddings).astype(np.float64).reshape(len(embeddings), -1)
    y = _numpy(label).astype(np.float64).reshape(-1)
    if len(x) != len(y):
        raise ValueError(f"embeddings ({len(x)}) and labels ({len(y)}) differ in length.")
    if not np.isfinite(y).all():
        raise ValueError("graded_probe: the labels must be finite.")
    nan = float("nan")
    if len(y) < MIN_GRADED:
        return GradedProbeResult(nan, nan, 0, 0)
    x_train, x_test, y_train, y_test = train_test_split(
        x, y, test_size=test_fraction, random_state=seed
    )
    if np.ptp(y_train) == 0 or np.ptp(y_test) == 0:
        return GradedProbeResult(nan, nan, len(y_train), len(y_test))
    model = make_pipeline(StandardScaler(), LinearRegression())
    with threadpool_limits(limits=1):  # as linear_probe: small fits, shared machines
        model.fit(x_train, y_train)
        predicted = model.predict(x_test)
    # A constant prediction (e.g. a collapsed embedding) has no ranking: Spearman is undefined.
    spearman = nan if np.ptp(predicted) == 0 else float(spearmanr(predicted, y_test).statistic)
    return GradedProbeResult(
        spearman=spearman,
        r2=float(r2_score(y_test, predicted)),
        n_train=len(y_train),
        n_test=len(y_test),
    )


def replay_graded_probe(
    replay_buffer,
    encoder,
    seed: int,
    label_key,
    bin_edges=None,
    per_bin: int = 500,
) -> GradedProbeResult:
    """The graded probe on a bin-balanced sample of a replay buffer's transitions.

    Up to ``per_bin`` transitions of each label bin (``bin_edges`` as the graded
    :class:`~s3rl_torchrl.data.SafeUnsafeSampler`'s; ``None``: one bin, up to ``per_bin``
    transitions in all) are drawn without replacement with a ``torch.Generator`` seeded by
    ``seed`` (the global RNGs are untouched). Balancing keeps the rare high-risk bins in the
    sample, as :func:`replay_probe` balances safe and unsafe. The label describes ``s_t``, the
    row's root ``"observation"``, which ``encoder`` embeds. Rows whose label is NaN (stored
    before the run stored the label) are left out.
    """
    storage = replay_buffer.storage
    size = len(storage)
    if size == 0:
        return graded_probe(np.zeros((0, 1)), np.zeros(0))
    stored = storage[:size]
    labels = stored.get(label_key).reshape(size, -1)[:, 0].float().cpu()
    if bin_edges is None:
        bins = torch.zeros(size, dtype=torch.long)
    else:
        edges = torch.tensor(list(bin_edges), dtype=labels.dtype)
        bins = torch.bucketize(labels, edges, right=True)
    # NaN: a step stored before its run stored the label (a resumed older checkpoint).
    bins[labels.isnan()] = -1
    generator = torch.Generator().manual_seed(int(seed))
    picked = []
    for k in range(int(bins.max()) + 1):
        index = (bins == k).nonzero().squeeze(-1)
        order = torch.randperm(len(index), generator=generator)[:per_bin]
        picked.append(index[order])
    if not picked:
        return graded_probe(np.zeros((0, 1)), np.zeros(0))
    index = torch.cat(picked)
    device = next(encoder.parameters()).device
    with torch.no_grad():
        states = stored[index].select(*encoder.in_keys).to(device)
        embeddings = encoder(states).get(encoder.out_keys[0])
    return graded_probe(embeddings, labels[index], seed=int(seed) % 2**32)
