"""Figures 2-4 of the paper from grouped runs (matplotlib, Agg backend; PNG and SVG).

Needs the ``plots`` extra (``pip install -e ".[plots]"``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from s3rl_torchrl.report.runs import RunGroup
from s3rl_torchrl.report.stats import learning_curve, summarize

if TYPE_CHECKING:  # the panels' type; importing it at run time would pull in torch
    from s3rl_torchrl.report.embeddings import EmbeddingPanel

__all__ = [
    "FORMATS",
    "critic_diagnostics",
    "embedding_tsne",
    "learning_curves",
    "safe_occupancy_bars",
]

FORMATS = ("png", "svg")
SAFE_COLOUR, UNSAFE_COLOUR = "#2ca02c", "#d62728"


def _pyplot():
    try:
        import matplotlib
    except ImportError as err:
        raise ImportError(
            "s3rl-report draws its figures with matplotlib: pip install -e \".[plots]\""
        ) from err
    matplotlib.use("Agg")
    # Rebuilding a report from the same runs gives the same SVG bytes (ids from a fixed salt,
    # no date; _save), so that committed figures change only when the results do.
    matplotlib.rcParams["svg.hashsalt"] = "s3rl-report"
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out_dir: Path, name: str) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for fmt in FORMATS:
        path = out_dir / f"{name}.{fmt}"
        metadata = {"Date": None} if fmt == "svg" else None
        fig.savefig(path, dpi=150, bbox_inches="tight", metadata=metadata)
        paths.append(path)
    fig.clf()
    return paths


# The reference in blue, the others in tab10's remaining colours, then tab20's light shades:
# 19 distinct colours before any repeats (a Table-2 sweep has ten algos).
PALETTE = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
    "#bcbd22", "#17becf", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5", "#c49c94", "#f7b6d2",
    "#c7c7c7", "#dbdb8d", "#9edae5",
]


def _colours(labels: Sequence[str], reference: str) -> dict[str, str]:
    """The reference algo in blue everywhere, every other label its own colour (PALETTE)."""
    others = [label for label in labels if label != reference]
    colours = {reference: PALETTE[0]}
    colours.update({label: PALETTE[1 + i % (len(PALETTE) - 1)] for i, label in enumerate(others)})
    return colours


def _ordered(groups: Sequence[RunGroup], reference: str) -> list[RunGroup]:
    return sorted(groups, key=lambda g: (g.algo != reference, g.label))


def _frames_formatter():
    """Tick labels 200k, 1M, ... that do not run into each other on a 1M-frame axis."""
    from matplotlib.ticker import FuncFormatter

    def label(x: float, _pos) -> str:
        if abs(x) >= 1e6:
            return f"{x / 1e6:g}M"
        return f"{x / 1e3:g}k" if abs(x) >= 1e3 else f"{x:g}"

    return FuncFormatter(label)


def learning_curves(
    by_task: Mapping[str, Sequence[RunGroup]], out_dir: Path, reference: str = "s3rl"
) -> list[Path]:
    """Figure 2: evaluation reward (top) and cost (bottom) against env frames, one column per
    task; mean over seeds, shaded +- std; the task's cost limit as a dashed line."""
    plt = _pyplot()
    tasks = list(by_task)
    labels = sorted({g.label for groups in by_task.values() for g in groups})
    legend_beside = len(labels) > 4  # many algos: one legend beside the plots, not over them
    legend_width = 2.6 if legend_beside else 0.0
    fig, axes = plt.subplots(
        2,
        len(tasks),
        figsize=(6.0 * len(tasks) + legend_width, 6.4),
        squeeze=False,
        sharex="col",
    )
    colours = _colours(labels, reference)
    for col, task in enumerate(tasks):
        for group in _ordered(by_task[task], reference):
            for row, column in enumerate(("eval/reward", "eval/cost")):
                frames, mean, std = learning_curve(group, column)
                if not len(frames):
                    continue
                ax = axes[row, col]
                colour = colours[group.label]
                seeds = len(group.runs)
                ax.plot(frames, mean, color=colour, label=f"{group.label} ({seeds} seeds)")
                # Costs are never negative: the band stops at 0 rather than suggest it.
                low = np.maximum(mean - std, 0.0) if column == "eval/cost" else mean - std
                ax.fill_between(frames, low, mean + std, color=colour, alpha=0.2, lw=0)
        limit = by_task[task][0].cost_limit
        if not math.isnan(limit):
            axes[1, col].axhline(limit, color="black", ls="--", lw=1, label=f"cost limit {limit:g}")
        axes[0, col].set_title(task, fontsize=10)
        axes[0, col].set_ylabel("evaluation reward")
        axes[1, col].set_ylabel("evaluation cost")
        axes[1, col].set_xlabel("environment steps")
        axes[1, col].xaxis.set_major_formatter(_frames_formatter())
        if not legend_beside:
            axes[1, col].legend(fontsize=8)
        elif col == len(tasks) - 1:
            axes[1, col].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
    fig.suptitle("Learning curves (deterministic evaluation; mean ± std over seeds)")
    fig.tight_layout()
    paths = _save(fig, out_dir, "figure2_learning_curves")
    plt.close(fig)
    return paths


#: The rows of the critic-diagnostics figure: (y label, [(column, line style), ...], log scale);
#: dashed: the discounted return that followed the steps the critic is read at.
CRITIC_PANELS = (
    ("cost critic Q_c", [("critic/cost_q", "-"), ("critic/cost_return", "--")], False),
    ("reward critic Q_r (soft)", [("critic/reward_q", "-"), ("critic/reward_return", "--")],
     False),
    ("alpha", [("train/alpha", "-")], True),
    ("cost share of |grad|", [("grad/cost_share", "-")], False),
)
#: Runs from before the critic diagnostics have no critic/*: their critics are drawn dotted from
#: the last gradient step's batch means at a ~ pi, which every version logs.
CRITIC_FALLBACK = {"critic/cost_q": "train/cost_q", "critic/reward_q": "train/reward_q"}


def critic_diagnostics(
    by_task: Mapping[str, Sequence[RunGroup]], out_dir: Path, reference: str = "s3rl"
) -> list[Path]:
    """The critics' health per epoch (diagnostics/critics.py columns of ``metrics.csv``): the
    cost and reward critics at the last finished training episodes' steps against the
    discounted returns that followed, alpha, and the share of the actor's gradient norm that
    comes from the cost term, ``|g_cost| / (|g_reward| + |g_entropy| + |g_cost|)``. One column
    per task, mean over seeds. A cost critic below 0 or a gradient share stuck at 1 shows."""
    plt = _pyplot()
    tasks = list(by_task)
    labels = sorted({g.label for groups in by_task.values() for g in groups})
    fig, axes = plt.subplots(
        len(CRITIC_PANELS), len(tasks), figsize=(6.0 * len(tasks), 11.0), squeeze=False,
        sharex="col",
    )
    colours = _colours(labels, reference)
    for col, task in enumerate(tasks):
        for group in _ordered(by_task[task], reference):
            colour = colours[group.label]
            for row, (_, columns, _log) in enumerate(CRITIC_PANELS):
                for column, style in columns:
                    frames, mean, _ = learning_curve(group, column)
                    if not len(frames) and column in CRITIC_FALLBACK:
                        frames, mean, _ = learning_curve(group, CRITIC_FALLBACK[column])
                        style = ":"
                    if not len(frames):
                        continue
                    label = f"{group.label} ({len(group.runs)} seeds)" if style != "--" else None
                    axes[row, col].plot(frames, mean, style, color=colour, label=label)
        axes[0, col].set_title(task, fontsize=10)
        for row, (label, _, log) in enumerate(CRITIC_PANELS):
            ax = axes[row, col]
            ax.set_ylabel(label, fontsize=8)
            if log:
                ax.set_yscale("log")
            if row < 2:
                ax.axhline(0.0, color="black", lw=0.8)
            ax.grid(alpha=0.3)
        axes[-1, col].set_ylim(-0.02, 1.02)
        axes[-1, col].set_xlabel("environment steps")
        axes[-1, col].xaxis.set_major_formatter(_frames_formatter())
    # One legend for all columns, below them: a selection's group labels are long and would
    # cover the curves inside an axis.
    handles: dict[str, object] = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    legend_share = min(0.4, 0.02 + 0.016 * len(handles))  # of the figure's height
    fig.set_size_inches(fig.get_figwidth(), 11.0 / (1.0 - legend_share))
    fig.legend(list(handles.values()), list(handles), loc="lower center", fontsize=8,
               frameon=False)
    fig.suptitle(
        "Critic diagnostics (mean over seeds; dashed: the returns that followed; dotted: runs "
        "without critic/*, train/*_q)"
    )
    fig.tight_layout(rect=(0.0, legend_share, 1.0, 1.0))
    paths = _save(fig, out_dir, "critic_diagnostics")
    plt.close(fig)
    return paths


def safe_occupancy_bars(
    by_task: Mapping[str, Sequence[RunGroup]], out_dir: Path, reference: str = "s3rl"
) -> list[Path]:
    """Figure 3: safe-state occupancy (% of final-evaluation steps with zero cost) per task and
    algo (mean over finished seeds, +- std), each baseline bar annotated with the reference's
    difference in percentage points."""
    plt = _pyplot()
    tasks = list(by_task)
    labels = sorted({g.label for groups in by_task.values() for g in groups})
    labels = sorted(labels, key=lambda label: (label != reference, label))
    colours = _colours(labels, reference)
    width = 0.8 / len(labels)
    fig, ax = plt.subplots(figsize=(max(5.0, 1.6 * len(tasks) * len(labels)), 4.2))
    in_legend: set[str] = set()
    for t, task in enumerate(tasks):
        groups = {g.label: g for g in by_task[task]}
        occupancy = {
            label: summarize(g).safe_occupancy_seeds for label, g in groups.items() if g.finished
        }
        ref = occupancy.get(reference)
        for i, label in enumerate(labels):
            if label not in occupancy:
                continue
            value = occupancy[label]
            x = t + (i - (len(labels) - 1) / 2) * width
            err = 0.0 if math.isnan(value.std) else value.std
            ax.bar(x, value.mean, width, yerr=err, color=colours[label], capsize=3,
                   label=None if label in in_legend else label)
            in_legend.add(label)
            text = f"{value.mean:.1f}%"
            if ref is not None and label != reference:
                text += f"\n{ref.mean - value.mean:+.1f} pp"
            ax.annotate(text, (x, value.mean + err), xytext=(0, 3), textcoords="offset points",
                        ha="center", va="bottom", fontsize=7)
    ax.set_xticks(range(len(tasks)), tasks, fontsize=8)
    ax.set_ylabel("safe-state occupancy (%)")
    ax.set_ylim(0, 118)
    ax.set_title(f"Safe-state occupancy in final evaluation (pp: {reference} minus that bar)")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    paths = _save(fig, out_dir, "figure3_safe_occupancy")
    plt.close(fig)
    return paths


def embedding_tsne(
    panels: Mapping[str, Mapping[str, EmbeddingPanel]], out_dir: Path
) -> list[Path]:
    """Figure 4: t-SNE of policy-encoder embeddings, safe vs unsafe states.

    ``panels[task][label]``: one row per task, one panel per algo (the reference first), each
    an :class:`~s3rl_torchrl.report.embeddings.EmbeddingPanel` (t-SNE already computed); the
    panel's title gives the linear probe's held-out accuracy / AUC.
    """
    plt = _pyplot()
    tasks = list(panels)
    cols = max(len(p) for p in panels.values())
    fig, axes = plt.subplots(len(tasks), cols, figsize=(4.2 * cols, 4.2 * len(tasks)),
                             squeeze=False)
    for r, task in enumerate(tasks):
        for c, (label, panel) in enumerate(panels[task].items()):
            ax = axes[r, c]
            xy, safe, probe = panel.xy, panel.safe.astype(bool), panel.probe
            ax.scatter(*xy[safe].T, s=4, c=SAFE_COLOUR, label=f"safe ({safe.sum()})", alpha=0.6)
            ax.scatter(*xy[~safe].T, s=4, c=UNSAFE_COLOUR, label=f"unsafe ({(~safe).sum()})",
                       alpha=0.8)
            probe_text = (
                f"probe acc {probe.accuracy:.2f} (chance {probe.chance:.2f}), AUC {probe.auc:.2f}"
                if probe.fitted else "probe: too few states of one class"
            )
            ax.set_title(f"{task}\n{label}\n{probe_text}", fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.legend(fontsize=7, markerscale=3)
        for c in range(len(panels[task]), cols):
            axes[r, c].axis("off")
    fig.suptitle("t-SNE of policy-encoder embeddings of evaluation states")
    fig.tight_layout()
    paths = _save(fig, out_dir, "figure4_embedding_tsne")
    plt.close(fig)
    return paths
