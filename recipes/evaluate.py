"""``python recipes/evaluate.py ...`` = ``s3rl-eval ...`` from a source checkout (a thin wrapper).

The recipe lives in :mod:`s3rl_torchrl.recipes.evaluate`; its configs are the top-level ``configs/``.
This directory is not installed: the console script points into the package.
"""

from s3rl_torchrl.recipes.evaluate import main

if __name__ == "__main__":
    main()
