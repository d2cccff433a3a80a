# Two entry points do all set-up on a fresh machine (Python >= 3.10 and nothing else):
#   make train   -> creates .venv on first use, then runs the main job
#   make test    -> creates .venv on first use, then lints and runs the test suite
#   (make test-fast: the same without the slow end-to-end tests)
# Override the torch build with e.g.  make test TORCH_SPEC="torch==2.13.0+cu128"
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
TORCH_SPEC ?=
EXTRAS ?= dev
# bullet-safety-gym pins gymnasium~=0.28.1 in its metadata but runs on Gymnasium 1.x, so it is
# installed without its dependency pins (its real dependency, pybullet, is the `bullet` extra,
# part of `dev`). Empty BULLET_SPEC skips it. See docs/installation.md.
BULLET_SPEC ?= bullet-safety-gym==1.4.0
STAMP := $(VENV)/.installed-$(EXTRAS)

# pytest-xdist workers for make test / test-fast (0: one process).
WORKERS ?= 2

.PHONY: setup train test test-fast lint bench report clips clean

$(STAMP): pyproject.toml constraints.txt Makefile
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	@if [ -n "$(TORCH_SPEC)" ]; then \
		echo "$(TORCH_SPEC)" > $(VENV)/constraints.txt; \
	else \
		cp constraints.txt $(VENV)/constraints.txt; \
	fi
	$(BIN)/python -m pip install --quiet -c $(VENV)/constraints.txt -e ".[$(EXTRAS)]"
	@if [ -n "$(BULLET_SPEC)" ]; then \
		$(BIN)/python -m pip install --quiet --no-deps "$(BULLET_SPEC)"; \
	fi
	@touch $(STAMP)

setup: $(STAMP)

train: $(STAMP)
	$(BIN)/s3rl-train $(ARGS)

lint: $(STAMP)
	$(BIN)/ruff check s3rl_torchrl recipes tests benchmarks docs

# Every test (CI runs this); test-fast leaves out the ones marked slow (end-to-end runs).
test: $(STAMP) lint
	$(BIN)/python -m pytest -q -n $(WORKERS) $(ARGS)

test-fast: $(STAMP) lint
	$(BIN)/python -m pytest -q -n $(WORKERS) -m "not slow" $(ARGS)

# The standing benchmarks in one table (benchmarks/run.py, docs/benchmarks.md; minutes), into
# benchmarks/results/standing/<date>.json. A subset or a smoke run: make bench ARGS="sampler --quick"
bench: $(STAMP)
	$(BIN)/python benchmarks/run.py $(ARGS)

# The clips of docs/media/ (docs/video.md): one GIF per task family, unsafe steps marked, of a
# short S3RL run it trains per task (minutes), or of given runs: make clips ARGS="--run TASK=DIR"
clips: $(STAMP)
	$(BIN)/python docs/make_clips.py $(ARGS)

# S3RL's graded (cost-to-go) and binary contrastive labels, compared by group label.
GRADED = s3rl (algo.contrastive_cfg.label=cost_to_go)
BINARY = s3rl (algo.contrastive_cfg.label=binary)

# Rebuild the reports in docs/ from the small result files kept in results/ (config.json,
# metrics.csv, final_eval.json per run; docs/results.md): the Table 1 reproduction and the
# Table 2 comparison of algorithms, the experiment=safe evidence (results/safe: FSRL's critics;
# results/safe_sound: the sound critics, the preset since issue 35; results/safe_sound_hopper_max:
# Hopper's first sound-critic runs, under the max read replaced by selection round 5), and the 300k-frame
# experiment=safe runs (SafetyPointGoal1, graded labels).
# What the critic selection's runs differ in besides the task (configs/sweep/critic_*.yaml).
SELECTION_GROUPS = --group-by algo.cost_critic_read --group-by algo.cost_nonnegative \
	--group-by algo.lagrangian_lr --group-by algo.lagrangian_warmup_frames \
	--group-by algo.update_per_step

report: $(STAMP)
	$(BIN)/s3rl-report results/reproduction --out docs/reproduction
	$(BIN)/s3rl-report lagrangian results/reproduction/*/seed* \
		--out docs/reproduction/lagrangian.json --plot docs/reproduction/lagrangian.png
	$(BIN)/s3rl-report results/safe --out docs/safe
	$(BIN)/s3rl-report lagrangian results/safe/*/seed* \
		--out docs/safe/lagrangian.json --plot docs/safe/lagrangian.png
	$(BIN)/s3rl-report results/safe_sound --out docs/safe_sound
	$(BIN)/s3rl-report lagrangian results/safe_sound/*/seed* \
		--out docs/safe_sound/lagrangian.json --plot docs/safe_sound/lagrangian.png
	$(BIN)/s3rl-report results/safe_sound_hopper_max --out docs/safe_sound_hopper_max
	$(BIN)/s3rl-report lagrangian results/safe_sound_hopper_max/*/seed* \
		--out docs/safe_sound_hopper_max/lagrangian.json \
		--plot docs/safe_sound_hopper_max/lagrangian.png
	$(BIN)/s3rl-report results/safe_300k --out docs/safe_300k \
		--group-by algo.contrastive_cfg.label --compare "$(GRADED):$(BINARY)"
	$(BIN)/s3rl-report lagrangian results/safe_300k/*/seed* \
		--out docs/safe_300k/lagrangian.json --plot docs/safe_300k/lagrangian.png
	$(BIN)/s3rl-report results/table2 --no-embeddings --out docs/table2 \
		--compare s3rl_ddpg_lag:ddpg_lag --compare s3rl_ppo_lag:ppo_lag --compare s3rl_nolag:sac
	$(BIN)/s3rl-report benchmarks/results/critic_selection --no-embeddings --no-aggregate \
		--reference sac_lag --out docs/critic_selection $(SELECTION_GROUPS)
	$(BIN)/s3rl-report lagrangian benchmarks/results/critic_selection/*/*/seed* \
		--out docs/critic_selection/lagrangian.json --plot docs/critic_selection/lagrangian.png
	$(BIN)/s3rl-report benchmarks/results/critic_selection_1m --no-embeddings --no-aggregate \
		--reference sac_lag --out docs/critic_selection_1m \
		--group-by algo.cost_critic_read --group-by algo.actor_lr
	$(BIN)/s3rl-report lagrangian benchmarks/results/critic_selection_1m/*/*/seed* \
		--out docs/critic_selection_1m/lagrangian.json --plot docs/critic_selection_1m/lagrangian.png
# Table 1 under one preset: the evidence tasks (results/safe_sound) and the nine others
# (results/table1, sweep=table1), one report with the aggregate over all of them. Built once
# the first table1 run is exported; until then docs/safe_sound is the same report. The tables
# of docs/results.md's "Table 1 in full" are rewritten from the same runs.
ifneq ($(wildcard results/table1),)
	$(BIN)/s3rl-report results/safe_sound results/table1 --no-embeddings --out docs/table1
	$(BIN)/python docs/update_table1.py
	$(BIN)/s3rl-report lagrangian results/table1/*/seed* \
		--out docs/table1/lagrangian.json --plot docs/table1/lagrangian.png
endif

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache .ruff_cache
