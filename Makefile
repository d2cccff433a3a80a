# Two entry points do all set-up on a fresh machine (Python >= 3.10 and nothing else):
#   make train   -> creates .venv on first use, then runs the main job
#   make test    -> creates .venv on first use, then lints and runs the test suite
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

.PHONY: setup train test lint bench clean

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
	$(BIN)/ruff check s3rl_torchrl recipes tests benchmarks

test: $(STAMP) lint
	$(BIN)/python -m pytest -q $(ARGS)

bench: $(STAMP)
	$(BIN)/python benchmarks/env_throughput.py

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache .ruff_cache
