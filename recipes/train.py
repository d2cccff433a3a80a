"""``python recipes/train.py ...`` = ``s3rl-train ...`` from a source checkout (a thin wrapper).

The recipe lives in :mod:`s3rl_torchrl.recipes.train`; its configs are the top-level ``configs/``.
This directory is not installed: the console script points into the package.
"""

from s3rl_torchrl.recipes.train import main

if __name__ == "__main__":
    main()
