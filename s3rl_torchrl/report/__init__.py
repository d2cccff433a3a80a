"""Results toolkit: ``s3rl-report`` turns run directories into the paper's tables and figures.

Submodules: :mod:`~s3rl_torchrl.report.runs` (find and group runs), :mod:`~.stats` (Table 1
and the S3RL-vs-baseline tests), :mod:`~.figures` (Figures 2-4, matplotlib), :mod:`~.embeddings` (policy-encoder embeddings
of evaluation rollouts, probed with :mod:`s3rl_torchrl.diagnostics`), :mod:`~.paper` (the
paper's numbers), :mod:`~.build` (``report.md``), the run analyses :mod:`~.lagrangian` (the
Lagrange multiplier's dynamics, ``s3rl-report lagrangian``) and :mod:`~.compare_runs` (do two
runs give the same metrics, ``s3rl-report compare-runs``), :mod:`~.records` (their JSON) and
:mod:`~.cli`. Importing this package imports none of them.
"""
