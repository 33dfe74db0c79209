# lidarcam: `make help` lists the targets.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export OMP_NUM_THREADS ?= 1
export OPENBLAS_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.DEFAULT_GOAL := help
.PHONY: help setup test test-slow lint bench reproduce-paper explain-paper corner-noise real-data leaderboard verify-results search-paper robustness plan-check clean clean-results

help: ## List the targets
	@grep -E '^[a-zA-Z_-]+:.*## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*## "}; {printf "  %-18s %s\n", $$1, $$2}'

$(STAMP): pyproject.toml
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "lidarcam needs Python 3.11+"'
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

setup: $(STAMP) ## Create .venv and install lidarcam with its dev tools

test: $(STAMP) ## Run the fast test suite (< 5 min on 2 cores)
	$(PY) -m pytest -n 2

test-slow: $(STAMP) ## Run only the slow, opt-in tests
	$(PY) -m pytest -m slow

lint: $(STAMP) ## ruff check
	$(VENV)/bin/ruff check .

bench: $(STAMP) ## Time calibrate() per method and the minimal solver's throughput
	$(PY) -m experiments.bench

PRESET ?=
TRIALS ?= 500
reproduce-paper: $(STAMP) ## Paper's sweeps -> results/paper/; PRESET=paper-matched [TRIALS=500]: -> results/paper-matched/
ifeq ($(strip $(PRESET)),)
	$(PY) -m experiments.reproduce
else
	$(PY) -m experiments.matched --preset $(PRESET) --trials $(TRIALS) --compare-trials $(TRIALS)
endif

search-paper: $(STAMP) ## Search the paper's unstated settings (conf/search/paper.yaml), write results/search/ and the preset
	$(PY) -m experiments.search --write-preset

explain-paper: $(STAMP) ## Ablations of peng2022 + unstated-setting sweeps, write results/explain/ (< 10 min on 2 cores)
	$(PY) -m experiments.explain

corner-noise: $(STAMP) ## Camera-noise sweeps (joint model over corners and ranges), write results/corner_noise/
	$(PY) -m experiments.corner_noise --trials 25 --boards-trials 25

REAL_DATA ?= ../shared/real-data
real-data: $(STAMP) ## The three public rigs end to end, write results/real/ (REAL_DATA=path to the data sets)
	$(PY) -m experiments.real_data --data $(REAL_DATA)

leaderboard: $(STAMP) ## Every registered method on conf/leaderboard/v1.yaml -> results/leaderboard/ (FULL=1: full counts; ARGS='methods.plugins=[my_lab.x]')
	$(PY) -m experiments.leaderboard $(if $(FULL),--full) $(ARGS)

verify-results: $(STAMP) ## Check that every stored trial chunk under results/ parses in full; list reports stale against the code
	$(PY) -m experiments.verify results

clean-results: ## Empty the trial stores under results/ (results/*/trials: every row is recomputed on the next run)
	rm -rf results/*/trials

robustness: $(STAMP) ## Wrong boards, outlier points, mixed pixels (experiment=outliers), write results/outliers/
	$(PY) -m experiments.outliers

plan-check: $(STAMP) ## The capture planner against the simulator (conf/plan/check.yaml), write results/plan/
	$(PY) -m experiments.plan_check

clean: ## Remove the virtual environment and caches
	rm -rf $(VENV) .pytest_cache .ruff_cache outputs multirun
