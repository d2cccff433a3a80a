"""``report.md`` and its figures from a directory of runs: what ``s3rl-report`` does."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from s3rl_torchrl.report.paper import (
    PAPER_TITLE,
    load_paper_results,
    paper_results_for,
    task_aliases,
)
from s3rl_torchrl.report.peers import peer_results_for
from s3rl_torchrl.report.runs import (
    PROTOCOLS,
    RUN_SPECIFIC_KEYS,
    ReportError,
    Run,
    RunGroup,
    config_differences,
    find_runs,
    group_runs,
    under_protocol,
)
from s3rl_torchrl.report.stats import (
    WITHIN_SEED_SHARE_MIN,
    MeanStd,
    TestResult,
    compare_groups,
    summarize,
)

__all__ = ["build_report", "export_embedding_panels", "Report"]

REPORT_FILE = "report.md"
OVER_LIMIT = "⚠"


@dataclass
class Report:
    path: Path  # report.md
    figures: list[Path] = field(default_factory=list)
    groups: list[RunGroup] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _ms(value: MeanStd, digits: int = 2) -> str:
    if value.n == 0 or math.isnan(value.mean):
        return "–"
    if math.isnan(value.std):
        return f"{value.mean:.{digits}f}"
    return f"{value.mean:.{digits}f} ± {value.std:.{digits}f}"


def _num(x: float, digits: int = 2) -> str:
    return "–" if x is None or math.isnan(x) else f"{x:.{digits}f}"


def _p(p: float) -> str:
    if math.isnan(p):
        return "–"
    return f"= {p:.2g}" if p >= 1e-4 else "< 1e-4"


def _test_cell(result: TestResult) -> str:
    if math.isnan(result.pvalue):
        return f"– ({result.note}; {result.n})" if result.n != "-" else f"– ({result.note})"
    note = f"; {result.note}" if result.note else ""
    return (
        f"p {_p(result.pvalue)}, CI [{_num(result.ci_low)}, {_num(result.ci_high)}] "
        f"({result.n}{note})"
    )


def _by_task(groups: Sequence[RunGroup]) -> dict[str, list[RunGroup]]:
    out: dict[str, list[RunGroup]] = {}
    for group in groups:
        out.setdefault(group.task, []).append(group)
    return out


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str = "") -> list[str]:
    align = align or "l" * len(header)
    sep = ["---:" if a == "r" else "---" for a in align]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def _protocol_groups(group: RunGroup):
    """(protocol label, the group read under it) for every protocol its runs were evaluated
    with (``runs.PROTOCOLS``)."""
    for protocol, label in PROTOCOLS.items():
        read = under_protocol(group, protocol)
        if read is not None and read.finished:
            yield label, read


def _table1(by_task: dict[str, list[RunGroup]], reference: str) -> list[str]:
    rows = []
    for task, groups in by_task.items():
        for group in sorted(groups, key=lambda g: (g.algo != reference, g.label)):
            for protocol, read in _protocol_groups(group):
                s = summarize(read)
                marker = f" {OVER_LIMIT}" if s.over_limit else ""
                rows.append([
                    task, group.label, str(len(s.seeds)),
                    _ms(s.reward_seeds), _ms(s.reward_episodes),
                    _ms(s.cost_seeds) + marker, _ms(s.cost_episodes),
                    f"{s.cost_limit:g}", _ms(s.length_seeds, 1), _ms(s.safe_occupancy_seeds, 1),
                    protocol,
                ])
    header = ["task", "algo", "seeds", "reward (seeds)", "reward (episodes)", "cost (seeds)",
              "cost (episodes)", "cost limit", "length", "safe steps (%)", "evaluated"]
    return _table(header, rows, "llrrrrrrrrl")


def _finished_groups_of(by_task: dict[str, list[RunGroup]], paper_task: str) -> list[RunGroup]:
    """The groups with finished runs of a paper task, under any of its ids."""
    names = task_aliases(paper_task)
    return [g for task, groups in by_task.items() if task in names for g in groups if g.finished]


def _table1_coverage(by_task: dict[str, list[RunGroup]], reference: str) -> list[str]:
    """Which of the paper's Table 1 tasks have finished runs here of both the reference and
    another algo: a partial reproduction says what it leaves out."""
    paper_tasks = sorted({v.task for v in load_paper_results() if v.table == "Table 1"})
    covered, missing = [], []
    for paper_task in paper_tasks:
        algos = {g.algo for g in _finished_groups_of(by_task, paper_task)}
        (covered if reference in algos and len(algos) > 1 else missing).append(paper_task)
    if not covered:
        return []
    line = (f"The paper's Table 1 has {len(paper_tasks)} tasks; {len(covered)} of them "
            f"{'has' if len(covered) == 1 else 'have'} finished runs of {reference} and another "
            "algo here")
    if missing:
        line += ". Not (yet) here: " + ", ".join(missing)
    return [line + ".", ""]


def _differences(
    by_task: dict[str, list[RunGroup]], reference: str, pairs: Sequence[tuple[str, str]] = ()
) -> list[str]:
    rows = []
    for task, groups in by_task.items():
        finished = [g for g in groups if g.finished]
        compared = [(ref, base) for ref in finished if ref.algo == reference
                    for base in finished if base.algo != reference]
        # --compare A:B adds A minus B (e.g. s3rl_ddpg_lag:ddpg_lag) to the reference's rows.
        # A and B name algos or groups (a label as the tables print it, for groups split by
        # --group-by: two S3RL variants are one algo).
        for first, second in pairs:
            for a in finished:
                for b in finished:
                    new = a is not b and _names(a, first) and _names(b, second)
                    if new and not any(a is x and b is y for x, y in compared):
                        compared.append((a, b))
        for ref, base in compared:
            for protocol, label in PROTOCOLS.items():
                ref_read, base_read = under_protocol(ref, protocol), under_protocol(base, protocol)
                if ref_read is None or base_read is None:
                    continue
                for metric in ("reward", "cost"):
                    paired, welch = compare_groups(ref_read, base_read, metric)
                    rows.append([
                        task, metric, f"{ref.label} − {base.label}",
                        _num(paired.difference), _test_cell(paired),
                        _num(welch.difference), _test_cell(welch), label,
                    ])
    if not rows:
        return [f"No task has finished runs of both {reference} and another algo."]
    header = ["task", "metric", "difference", "over seeds", "paired t-test",
              "over episodes", "Welch t-test", "evaluated"]
    return _table(header, rows, "lllrlrll")


def _names(group: RunGroup, name: str) -> bool:
    """Whether ``--compare``'s ``name`` is ``group``'s algo or its label."""
    return name in (group.algo, group.label)


def _paper_comparison(by_task: dict[str, list[RunGroup]]) -> list[str]:
    rows = []
    for task, groups in by_task.items():
        values = paper_results_for(task)
        if not values:
            continue
        for group in groups:
            if not group.finished or group.extra:
                continue
            mine = [v for v in values if v.algo == group.algo and v.metric in ("reward", "cost")]
            for table in sorted({v.table for v in mine}):
                paper = {v.metric: v for v in mine if v.table == table}
                lengths = [v for v in values if v.table == table and v.metric == "length"]
                setting = next(iter(paper.values()))
                for protocol, read in _protocol_groups(group):
                    s = summarize(read)
                    ours = {"reward": s.reward_episodes.mean, "cost": s.cost_episodes.mean}
                    beyond = [m for m in ("reward", "cost") if m in paper
                              and abs(ours[m] - paper[m].mean) > paper[m].std]
                    rows.append([
                        task, group.algo, f"{table} ({setting.method}, {setting.setting})",
                        _ms(s.reward_episodes), _paper(paper.get("reward")),
                        _ms(s.cost_episodes), _paper(paper.get("cost")),
                        _ms(s.length_seeds, 1), _paper(lengths[0] if lengths else None, 1),
                        ", ".join(beyond) or "–", protocol,
                    ])
    if not rows:
        return ["The paper reports none of these tasks (or none of these algos)."]
    header = ["task", "algo", "paper's row", "reward (ours)", "reward (paper)", "cost (ours)",
              "cost (paper)", "length (ours)", "length (paper)", "beyond the paper's std",
              "ours evaluated"]
    return _table(header, rows, "lllrrrrrrll")


def _table1_full(by_task: dict[str, list[RunGroup]]) -> list[str]:
    """The paper's Table 1, every task in its order with each of its algos' rows, and ours
    beside each under both protocols ("–" where this report has no finished run of it)."""
    table1 = [v for v in load_paper_results() if v.table == "Table 1" and v.algo]
    # The last policy and FSRL's best-feasible checkpoint always; the delivered pick where a
    # run of the report has one (eval.delivery_epochs).
    protocols = {
        protocol: label for protocol, label in PROTOCOLS.items()
        if protocol != "delivered" or any(
            under_protocol(g, protocol) is not None for groups in by_task.values() for g in groups
        )
    }
    rows = []
    for paper_task in dict.fromkeys(v.task for v in table1):
        ours = {g.algo: g for g in _finished_groups_of(by_task, paper_task) if not g.extra}
        for algo in dict.fromkeys(v.algo for v in table1):
            paper = {v.metric: v for v in table1 if v.task == paper_task and v.algo == algo}
            cells = []
            for protocol in protocols:
                read = under_protocol(ours[algo], protocol) if algo in ours else None
                if read is None or not read.finished:
                    cells.append("–")
                    continue
                s = summarize(read)
                cells.append(f"{s.reward_episodes.mean:.2f} / {s.cost_episodes.mean:.2f}"
                             + (f" {OVER_LIMIT}" if s.over_limit else "")
                             + f" ({len(s.seeds)})")
            rows.append([paper_task, paper["reward"].method,
                         f"{paper['reward'].mean:.2f} / {paper['cost'].mean:.2f}", *cells])
    if all(row[3] == "–" for row in rows):
        return []
    header = ["task (the paper's id)", "algo", "paper: reward / cost",
              *(f"ours, {label}: reward / cost (seeds)" for label in protocols.values())]
    return ["### Table 1 in full", "",
            "Every task and algo of the paper's Table 1, in its order; ours are means over the "
            f"pooled final-evaluation episodes; {OVER_LIMIT}: over the cost limit (mean over "
            "seeds); –: no finished run of it in this report.", "",
            *_table(header, rows, "lll" + "r" * len(protocols)), ""]


def _paper(value, digits: int = 2) -> str:
    if value is None:
        return "–"
    return f"{value.mean:.{digits}f} ± {value.std:.{digits}f}"


def _frames(frames: int) -> str:
    if frames <= 0:
        return "–"
    return f"{frames / 1e6:g}M" if frames >= 1_000_000 else f"{frames // 1000}k"


def _peer_value(mean: float, std: float, approximate: bool) -> str:
    if math.isnan(mean):
        return "–"
    text = f"~{mean:g}" if approximate else f"{mean:.2f}"
    return text if math.isnan(std) else f"{text} ± {std:.2f}"


def _peer_comparison(by_task: dict[str, list[RunGroup]]) -> list[str]:
    """Per task with published peer results: our finished groups (pooled episodes, as the
    paper comparison) and then the peers' rows, each with its frames and cost limit."""
    rows = []
    for task, groups in by_task.items():
        peers = peer_results_for(task)
        if not peers:
            continue
        for group in groups:
            if not group.finished or group.extra:
                continue
            frames = group.runs[0].config.get("collector", {}).get("total_frames", 0)
            for protocol, read in _protocol_groups(group):
                s = summarize(read)
                rows.append([task, "ours", f"{group.label}, {protocol}", _frames(frames),
                             _num(group.cost_limit, 0), _ms(s.reward_episodes),
                             _ms(s.cost_episodes)])
        for peer in peers:
            cost = _peer_value(peer.cost, peer.cost_std, peer.approximate)
            if math.isnan(peer.cost):
                cost = f"≤ {peer.cost_limit:g}"
            rows.append([task, peer.source, peer.method, _frames(peer.frames),
                         "–" if math.isnan(peer.cost_limit) else f"{peer.cost_limit:g}",
                         _peer_value(peer.reward, peer.reward_std, peer.approximate), cost])
    if not rows:
        return ["No peer has published results on these tasks (`report/data/peer_results.csv`)."]
    header = ["task", "who", "what", "frames", "cost limit", "reward", "cost"]
    return _table(header, rows, "llllrrr")


def _occupancy(by_task: dict[str, list[RunGroup]], reference: str) -> list[str]:
    rows = []
    for task, groups in by_task.items():
        finished = {g.label: summarize(g) for g in groups if g.finished}
        ref = next((s for g, s in zip(groups, map(summarize, groups))
                    if g.algo == reference and g.finished), None)
        for label, s in sorted(finished.items(), key=lambda kv: (kv[0] != reference, kv[0])):
            diff = "" if ref is None or label == reference else (
                f"{ref.safe_occupancy_seeds.mean - s.safe_occupancy_seeds.mean:+.1f}"
            )
            paper = [v for v in paper_results_for(task) if v.metric == "safe_occupancy_diff_pp"]
            paper_diff = f"{paper[0].mean:+.1f}" if paper and label == "sac_lag" else ""
            rows.append([task, label, _ms(s.safe_occupancy_seeds, 1), diff, paper_diff])
    header = ["task", "algo", "safe steps (%)", f"{reference} minus this (pp)",
              "paper: S3RL minus SAC-LAG (pp)"]
    return _table(header, rows, "llrrr")


def _last_logged(group: RunGroup, column: str) -> MeanStd:
    """The last logged value of a metrics.csv column in each finished run, over seeds."""
    last = []
    for run in group.finished:
        values = run.column(column)[1]
        if values:
            last.append(values[-1])
    return MeanStd.of(last, ddof=1)


def _training_probe(group: RunGroup) -> tuple[MeanStd, MeanStd]:
    """The last logged probe accuracy / AUC of each finished run, over seeds."""
    return _last_logged(group, "probe/accuracy"), _last_logged(group, "probe/auc")


def _graded_probe(by_task: dict[str, list[RunGroup]], reference: str) -> list[str]:
    """The graded probe per group: the last logged ``probe/spearman`` and ``probe/r2``, with
    the label the contrastive phase was trained on and the label probed (the run's graded
    label, else the cost-to-go: ``hooks.labels.probed_label``); empty if no run logged it."""
    from s3rl_torchrl.hooks.labels import probed_label

    rows = []
    for task, groups in by_task.items():
        for group in sorted(groups, key=lambda g: (g.algo != reference, g.label)):
            spearman, r2 = _last_logged(group, "probe/spearman"), _last_logged(group, "probe/r2")
            if spearman.n or r2.n:
                algo = group.runs[0].config["algo"]
                label = algo.get("contrastive_cfg", {}).get("label", "binary")
                contrastive_algo = bool(algo.get("contrastive", False))
                probed = probed_label(contrastive_algo, label)
                trained = label if contrastive_algo else "none"
                rows.append([task, group.label, trained, probed,
                             str(max(spearman.n, r2.n)), _ms(spearman), _ms(r2)])
    if not rows:
        return []
    return [
        "## The graded probe (training)",
        "",
        "Does the policy encoder order states by a graded label? The `probe/spearman` "
        "(held-out Spearman correlation) and `probe/r2` (held-out R^2 of a linear regression "
        "from the embedding to the label) columns of `metrics.csv` at the last epoch, mean ± "
        "std over finished seeds. The probed label is the one the contrastive phase was "
        "trained on, or the cost-to-go for binary runs and algos without the phase "
        "(docs/representation.md).",
        "",
        *_table(["task", "algo", "contrastive label", "probed label", "seeds", "Spearman",
                 "R^2"], rows, "llllrrr"),
        "",
    ]


def _figure4_run(group: RunGroup) -> tuple[Run | None, str]:
    """The run Figure 4 shows for ``group`` and where its panel comes from: the lowest finished
    seed with a checkpoint to roll out, else with a stored panel (an exported tree)."""
    from s3rl_torchrl.report.embeddings import PANEL_FILES

    for run in group.finished:
        if run.checkpoint is not None:
            return run, "checkpoint"
    for run in group.finished:
        if all((run.path / name).is_file() for name in PANEL_FILES):
            return run, "stored"
    return None, ""


def _embedding_panels(
    by_task: dict[str, list[RunGroup]],
    reference: str,
    episodes: int,
    tsne_states: int,
    notes: list[str],
) -> tuple[dict, list[list[str]]]:
    """One panel per group: a checkpoint rolled out, embedded, probed and t-SNE'd, or the panel
    stored beside an exported run."""
    from s3rl_torchrl.report.embeddings import embedding_panel, load_panel

    panels: dict[str, dict] = {}
    rows = []
    for task, groups in by_task.items():
        for group in sorted(groups, key=lambda g: (g.algo != reference, g.label)):
            run, source = _figure4_run(group)
            if run is None:
                notes.append(f"Figure 4: no finished run of {task} / {group.label} has a "
                             "checkpoint (checkpoints/latest) or a stored panel "
                             "(figure4_states.csv); left out.")
                continue
            if source == "checkpoint":
                max_steps = run.config.get("eval", {}).get("max_steps")  # None: task's length
                panel = embedding_panel(run.checkpoint, episodes, max_steps, tsne_states)
            else:
                panel = load_panel(run.path)
            panels.setdefault(task, {})[f"{group.label} (seed {run.seed})"] = panel
            probe = panel.probe
            train_acc, train_auc = _training_probe(group)
            rows.append([
                task, group.label, str(run.seed), str(panel.episodes),
                f"{probe.n_safe} / {probe.n_unsafe}",
                f"{_num(probe.accuracy)} ({_num(probe.chance)})", _num(probe.auc),
                _ms(train_acc), _ms(train_auc),
            ])
    return panels, rows


def export_embedding_panels(
    root: str | Path, dest: str | Path, episodes: int = 2, tsne_states: int = 1000
) -> list[Path]:
    """Store Figure 4's panel of each group below ``root`` beside its copy below ``dest`` (as
    ``export_runs`` laid it out), so that ``s3rl-report DEST`` draws Figure 4 without the
    checkpoints; panels of the group's other runs left by an earlier export are removed.
    Returns the run directories that got one."""
    from s3rl_torchrl.report.embeddings import PANEL_FILES, embedding_panel, save_panel

    root, dest = Path(root), Path(dest)
    stored = []
    for group in group_runs(find_runs(root)):
        run, source = _figure4_run(group)
        if source != "checkpoint":
            continue  # no checkpoint: keep whatever the tree already holds
        max_steps = run.config.get("eval", {}).get("max_steps")
        target = dest / run.path.relative_to(root)
        save_panel(embedding_panel(run.checkpoint, episodes, max_steps, tsne_states), target)
        # One panel per group: an earlier export's panel on another seed would be drawn
        # instead of this one if that seed were lower.
        for other in group.runs:
            if other is not run:
                for name in PANEL_FILES:
                    (dest / other.path.relative_to(root) / name).unlink(missing_ok=True)
        stored.append(target)
    return stored


def _critic_table(groups: Sequence[RunGroup]) -> list[str]:
    """One row per group: how often the cost critic was below 0 and how far off it was, the
    largest alpha, and the cost term's share of the actor gradient over the last 20% of
    epochs; means over seeds."""
    lines = [
        "| task | algo | epochs with cost Q < 0 | cost Q - cost return (last 20%) | "
        "max alpha | cost share of the actor gradient (last 20%) |",
        "|---|---|---:|---:|---:|---:|",
    ]

    def tail(values: list[float]) -> list[float]:
        values = [v for v in values if not math.isnan(v)]
        return values[-max(1, len(values) // 5):] if values else []

    for group in groups:
        negative, bias, alpha, share = [], [], [], []
        for run in group.runs:
            rows = run.metrics
            column = "critic/cost_q" if rows and "critic/cost_q" in rows[0] else "train/cost_q"
            cost_q = [r.get(column, math.nan) for r in rows]
            known = [v for v in cost_q if not math.isnan(v)]
            negative.append(sum(v < 0 for v in known) / len(known) if known else math.nan)
            bias += tail([r.get("critic/cost_error", math.nan) for r in rows])
            alpha += [r.get("train/alpha", math.nan) for r in rows]
            share += tail([r.get("grad/cost_share", math.nan) for r in rows])

        def fmt(values: list[float], spec: str, reduce=np.mean) -> str:
            values = [v for v in values if not math.isnan(v)]
            return format(float(reduce(values)), spec) if values else "-"

        lines.append(
            f"| {group.task} | {group.label} | {fmt(negative, '.0%')} | {fmt(bias, '.2f')} | "
            f"{fmt(alpha, '.3g', np.max)} | {fmt(share, '.2f')} |"
        )
    return lines


def build_report(
    root: str | Path | Sequence[str | Path],
    out: str | Path | None = None,
    reference: str = "s3rl",
    group_by: Sequence[str] = (),
    pairs: Sequence[tuple[str, str]] = (),
    embeddings: bool = True,
    embedding_episodes: int = 2,
    tsne_states: int = 1000,
    command: str | None = None,
    aggregate: bool | None = None,
    aggregate_reps: int = 2000,
    aggregate_seed: int = 0,
) -> Report:
    """Find the runs below ``root``, write ``<out>/report.md`` and its figures (PNG and SVG).

    Args:
        root: a run, a Hydra multirun, or any directory with runs below it; or several of
            them, reported as one (e.g. two exported results trees that together cover the
            paper's Table 1). A seed of one group found below two of them is an error.
        out: the report directory (default ``<root>/report``, the first root's).
        reference: the algo compared against every other one (S3RL).
        group_by: config keys (dotted) that split runs of one task and algo into groups.
        pairs: further (algo, algo) pairs whose difference is tested, first minus second.
        embeddings: draw Figure 4 and the probe table, from each group's checkpoint rolled
            out (a few seconds per checkpoint plus t-SNE) or, without one, from the panel
            ``--export-runs`` stored.
        embedding_episodes: evaluation env copies rolled out per checkpoint.
        tsne_states: at most this many states per t-SNE panel.
        command: the command line shown in the report.
        aggregate: the aggregate over tasks (``report.aggregate``, rliable): True: required
            (a ReportError without rliable), False: left out, None: included when rliable
            imports, else the section says what to install.
        aggregate_reps: bootstrap resamples of each aggregate estimate.
        aggregate_seed: the seed of the aggregate's bootstrap (same seed, same intervals).
    """
    roots = [Path(root)] if isinstance(root, (str, Path)) else [Path(r) for r in root]
    if not roots:
        raise ReportError("No runs directory given.")
    out = Path(out) if out is not None else roots[0] / "report"
    runs = [run for r in roots for run in find_runs(r)]
    groups = group_runs(runs, group_by)
    by_task = _by_task(groups)
    report = Report(out / REPORT_FILE, groups=groups)
    out.mkdir(parents=True, exist_ok=True)

    lines = _title_section(runs, roots, groups, group_by, command, report)
    _note_setting_differences(by_task, group_by, report)
    lines += _table1_section(by_task, reference)
    lines += _differences_section(by_task, reference, pairs)
    lines += _paper_section(by_task)
    lines += _peers_section(by_task)
    if aggregate is not False:
        lines += _aggregate_section(
            groups, out, reference, pairs, aggregate, aggregate_reps, aggregate_seed, report
        )
    lines += _figure2_section(by_task, out, reference, report)
    lines += _critic_section(groups, by_task, out, reference, report)
    finished = any(r.finished for r in runs)
    if finished:
        lines += _figure3_section(by_task, out, reference, report)
    lines += _figure4_section(
        by_task, out, reference, embeddings and finished, embedding_episodes, tsne_states,
        report,
    )
    lines += _graded_probe(by_task, reference)
    lines += _notes_section(report.notes)
    report.path.write_text("\n".join(lines))
    return report


# ------------------------------------------------------------------------------ the sections
# Each returns its lines of report.md (a heading, its text, its tables, a blank line) and adds
# its figure files and notes to the report.
def _title_section(
    runs: Sequence[Run],
    roots: Sequence[Path],
    groups: Sequence[RunGroup],
    group_by: Sequence[str],
    command: str | None,
    report: Report,
) -> list[str]:
    """The title, what the report was generated from, and the unfinished runs."""
    finished = [r for r in runs if r.finished]
    where = ", ".join(f"`{r}`" for r in roots)
    lines = [
        "# S3RL results report",
        "",
        f"Generated by `{command or 's3rl-report ' + ' '.join(map(str, roots))}` from "
        f"{len(runs)} runs below {where} ({len(finished)} finished) in {len(groups)} groups (task × algo"
        + (f" × {', '.join(group_by)}" if group_by else "") + ").",
        "",
    ]
    unfinished = [r for r in runs if not r.finished]
    if unfinished:
        lines += ["## Unfinished runs", "",
                  "No `final_eval.json`: left out of the tables, kept in the learning curves.",
                  ""]
        lines += [f"- `{r.path}`: {r.task} / {r.algo} seed {r.seed}, "
                  f"{r.frames} of {r.total_frames} frames" for r in unfinished]
        lines.append("")
    if not finished:
        report.notes.append("No run is finished: the tables are empty.")
    return lines


def _note_setting_differences(
    by_task: dict[str, list[RunGroup]], group_by: Sequence[str], report: Report
) -> None:
    """A note per task whose algos were run with different settings besides the algo (algos
    of one task compared with each other should differ in the algo only)."""
    for task, task_groups in by_task.items():
        firsts = [g.runs[0] for g in task_groups]
        diff = config_differences(firsts, (*RUN_SPECIFIC_KEYS, "algo", *group_by))
        if diff:
            keys = ", ".join(f"`{k}` ({' / '.join(map(str, v))})" for k, v in diff.items())
            report.notes.append(
                f"{task}: the algos compared were run with different settings besides the "
                f"algo: {keys} (in the order {', '.join(g.label for g in task_groups)})."
            )


def _table1_section(by_task: dict[str, list[RunGroup]], reference: str) -> list[str]:
    """Table 1 (the final deterministic evaluation) and which of the paper's cells it covers."""
    return [
        "## Table 1: final deterministic evaluation",
        "",
        "Mean ± std of the final evaluation (`final_eval.json`). *evaluated*: the policy at "
        "the end of training (*last policy*), or the checkpoint FSRL's trainer keeps "
        "(*best-feasible checkpoint*: the epoch with the highest evaluation reward among those "
        "within the cost limit, or, before any is, the first within it or the highest reward; "
        "`fsrl/trainer/base_trainer.py`, `perf_is_better`), evaluated with the same episodes "
        "at the end; the paper does not say which it reports. *seeds*: one value per seed "
        "(its mean over episodes), sample std over seeds. *episodes*: all evaluation episodes "
        "of all seeds pooled (population std), as the paper's Table 1 reports. "
        f"{OVER_LIMIT}: mean cost over seeds above the task's cost limit.",
        "",
        *_table1(by_task, reference),
        "",
        *_table1_coverage(by_task, reference),
    ]


def _differences_section(
    by_task: dict[str, list[RunGroup]], reference: str, pairs: Sequence[tuple[str, str]]
) -> list[str]:
    """The reference against every other algo (and ``pairs``): differences and their tests."""
    return [
        f"## {reference} vs the other algos",
        "",
        f"Difference of means ({reference} minus the other). Paired t-test over the seeds both "
        "algos ran (runs paired by seed; seeds present for only one are left out); Welch's "
        "t-test over the pooled evaluation episodes; 95% confidence intervals of the "
        "difference (scipy.stats `ttest_rel` / `ttest_ind(equal_var=False)`). The test over "
        "episodes is flagged where less than "
        f"{WITHIN_SEED_SHARE_MIN:.0%} of a group's variance over episodes is within seeds: "
        "its episodes are then near copies of one seed's policy, not independent samples, "
        "and only the test over seeds means anything.",
        "",
        *_differences(by_task, reference, pairs),
        "",
    ]


def _paper_section(by_task: dict[str, list[RunGroup]]) -> list[str]:
    """The paper's Tables 1 and 2 beside ours, then the full Table 1 of the paper's tasks."""
    return [
        "## Comparison with the paper",
        "",
        f"The paper's numbers (\"{PAPER_TITLE}\", Table 1: 10 evaluation episodes after "
        "training; Table 2: ablation after 100 epochs) beside ours (pooled episodes). Ours are "
        "whatever these runs' settings are: compare only runs at the paper's settings "
        "(`experiment=paper`). *beyond the paper's std*: the metrics whose mean here is "
        "further from the paper's mean than the paper's own std (its spread over episodes): "
        "where the difference needs a reason (settings, task version, protocol).",
        "",
        *_paper_comparison(by_task),
        "",
        *_table1_full(by_task),
    ]


def _peers_section(by_task: dict[str, list[RunGroup]]) -> list[str]:
    """OmniSafe's, FSRL's and DSRL's published numbers on these tasks, beside ours."""
    return [
        "## Beside other libraries' published results",
        "",
        "What OmniSafe's off-policy benchmark (Table 2: 10 evaluation episodes over several "
        "seeds, mean ± std), FSRL's benchmark (final training reward and cost of 3 seeds, "
        "read off its curves: ~) and DSRL's dataset (the best reward of any trajectory within "
        "cost 10: what a feasible policy can earn) report on these tasks, beside ours (pooled "
        "episodes, last policy and best-feasible checkpoint). Other code at other frames and "
        "cost limits: for orientation, not a test. Sources: "
        "`s3rl_torchrl/report/data/peer_results.csv`.",
        "",
        *_peer_comparison(by_task),
        "",
    ]


def _aggregate_section(
    groups: Sequence[RunGroup],
    out: Path,
    reference: str,
    pairs: Sequence[tuple[str, str]],
    required: bool | None,
    reps: int,
    seed: int,
    report: Report,
) -> list[str]:
    """The aggregate over tasks (``report.aggregate``); ``required``: a ReportError without
    rliable (None: the section says what to install)."""
    from s3rl_torchrl.report.aggregate import aggregate_section, rliable_problem

    if required and rliable_problem() is not None:
        raise ReportError(f"--aggregate: {rliable_problem()}")
    section, files, notes = aggregate_section(groups, out, reference, pairs, reps, seed)
    report.figures += files
    report.notes += notes
    return section


def _figure2_section(
    by_task: dict[str, list[RunGroup]], out: Path, reference: str, report: Report
) -> list[str]:
    """Figure 2: the learning curves of every run, unfinished ones included."""
    from s3rl_torchrl.report import figures

    report.figures += figures.learning_curves(by_task, out, reference)
    return [
        "## Figure 2: learning curves",
        "",
        "Evaluation reward and cost per epoch (`metrics.csv`) against environment steps; mean "
        "over seeds, shaded ± std; every run, unfinished ones included; dashed: cost limit.",
        "",
        "![Figure 2](figure2_learning_curves.png)",
        "",
    ]


def _critic_section(
    groups: Sequence[RunGroup],
    by_task: dict[str, list[RunGroup]],
    out: Path,
    reference: str,
    report: Report,
) -> list[str]:
    """The critic diagnostics of the groups that logged them (none: no section)."""
    from s3rl_torchrl.report import figures

    # Runs of every version log train/cost_q; runs since the critic diagnostics also critic/*.
    diagnosed = [g for g in groups if any("train/cost_q" in r.metrics[0] for r in g.runs
                                          if r.metrics)]
    if not diagnosed:
        return []
    diagnosed_by_task = {
        task: [g for g in task_groups if g in diagnosed]
        for task, task_groups in by_task.items()
    }
    diagnosed_by_task = {t: gs for t, gs in diagnosed_by_task.items() if gs}
    report.figures += figures.critic_diagnostics(diagnosed_by_task, out, reference)
    return [
        "## Critic diagnostics",
        "",
        "Per epoch (`critic/*`, `grad/*` and `train/alpha` of `metrics.csv`): the cost and "
        "reward critics at the steps of the last 10 finished training episodes against the "
        "discounted returns that followed them, alpha, and the share of the actor's gradient "
        "norm that the `lambda Q_c` term makes (docs/objectives.md, \"Critic diagnostics\"). "
        "Runs written before those columns existed count their negative cost critics on "
        "`train/cost_q` (the last gradient step's batch mean at `a ~ pi`), draw it and "
        "`train/reward_q` dotted in the figure, and show `-` for the rest.",
        "",
        *_critic_table(diagnosed),
        "",
        "![Critic diagnostics](critic_diagnostics.png)",
        "",
    ]


def _figure3_section(
    by_task: dict[str, list[RunGroup]], out: Path, reference: str, report: Report
) -> list[str]:
    """Figure 3: the safe-state occupancy of the final evaluation (finished runs)."""
    from s3rl_torchrl.report import figures

    report.figures += figures.safe_occupancy_bars(by_task, out, reference)
    return [
        "## Figure 3: safe-state occupancy",
        "",
        "Percentage of final-evaluation steps with zero cost, mean ± std over seeds; pp: "
        f"percentage points, {reference} minus the other algo.",
        "",
        "![Figure 3](figure3_safe_occupancy.png)",
        "",
        *_occupancy(by_task, reference),
        "",
    ]


def _remove(paths: list[Path]) -> None:
    for path in paths:
        path.unlink(missing_ok=True)


def _figure4_section(
    by_task: dict[str, list[RunGroup]],
    out: Path,
    reference: str,
    draw: bool,
    episodes: int,
    tsne_states: int,
    report: Report,
) -> list[str]:
    """Figure 4: the policy encoder's embeddings and their linear probe, when ``draw`` (the
    embeddings asked for and a run finished)."""
    from s3rl_torchrl.report import figures

    lines = ["## Figure 4: policy-encoder embeddings and linear probe", ""]
    # A figure an earlier build drew into the same directory would otherwise stay beside a
    # report that no longer shows it, drawn from runs that may have left the tree.
    stale = [out / f"figure4_embedding_tsne{suffix}" for suffix in (".png", ".svg")]
    if not draw:
        _remove(stale)
        return lines + ["Not drawn (`--no-embeddings`, or no finished run).", ""]
    panels, rows = _embedding_panels(by_task, reference, episodes, tsne_states, report.notes)
    if not panels:
        _remove(stale)
        return lines + ["No checkpoint to roll out and no stored panel.", ""]
    report.figures += figures.embedding_tsne(panels, out)
    return lines + [
        "States of deterministic evaluation rollouts of one checkpoint per algo "
        "(`checkpoints/latest` of the lowest finished seed; *rollouts*: env copies, "
        "each the task's episode length or `eval.max_steps`), embedded by the policy "
        "encoder and coloured by their label (safe: the step from that state costs "
        f"nothing; t-SNE of at most {tsne_states} of them, drawn with a fixed seed). "
        "An exported results tree (`--export-runs`) keeps each panel as "
        "`figure4_states.csv` / `figure4_probe.json` beside the run, drawn here when "
        "the checkpoint is gone. Probe (on all of them): a logistic regression "
        "predicting the label from the embedding, accuracy (chance: majority class) "
        "and ROC AUC on a held-out 30%. *training*: the `probe/accuracy` and "
        "`probe/auc` columns of `metrics.csv` at the last epoch (class-balanced "
        "replay-buffer sample), mean ± std over finished seeds.",
        "",
        "![Figure 4](figure4_embedding_tsne.png)",
        "",
        *_table(["task", "algo", "seed", "rollouts", "states safe / unsafe",
                 "probe accuracy (chance)", "probe AUC", "training probe accuracy",
                 "training probe AUC"], rows, "lllrrrrrr"),
        "",
    ]


def _notes_section(notes: Sequence[str]) -> list[str]:
    """The notes the sections gathered (none: no section)."""
    if not notes:
        return []
    return ["## Notes", "", *[f"- {note}" for note in notes], ""]
