"""Results toolkit: ``s3rl-report`` turns run directories into the paper's tables and figures.

Submodules: :mod:`~s3rl_torchrl.report.runs` (find and group runs), :mod:`~.stats` (Table 1
and the S3RL-vs-baseline tests), :mod:`~.figures` (Figures 2-4, matplotlib), :mod:`~.probe`
(the linear probe, also used by the trainer), :mod:`~.embeddings` (policy-encoder embeddings
of evaluation rollouts), :mod:`~.paper` (the paper's numbers), :mod:`~.build` (``report.md``)
and :mod:`~.cli`. Importing this package imports none of them (the trainer needs only the probe).
"""
