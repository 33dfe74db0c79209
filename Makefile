# lidarcam: `make help` lists the targets.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export OMP_NUM_THREADS ?= 1
export OPENBLAS_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.DEFAULT_GOAL := help
.PHONY: help setup test test-slow test-slurm lint bench reproduce-paper rig-like explain-paper corner-noise real-data leaderboard verify-results search-paper robustness plan-check clean clean-results

help: ## List the targets (durations: wall time on 2 idle cores from an empty store, as measured)
	@grep -E '^[a-zA-Z_-]+:.*## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*## "}; {printf "  %-18s %s\n", $$1, $$2}'

$(STAMP): pyproject.toml
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "lidarcam needs Python 3.11+"'
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

setup: $(STAMP) ## Create .venv and install lidarcam with its dev tools (~1.5 min, fresh)

test: $(STAMP) ## Run the fast test suite (~3-5 min; SHUFFLE=seed: random order)
	$(PY) -m pytest -n 2 $(if $(SHUFFLE),--shuffle $(SHUFFLE))

test-slow: $(STAMP) ## Run only the slow, opt-in tests (not measured as a whole; 100-board peng2022 ~2 min)
	$(PY) -m pytest -m slow

test-slurm: $(STAMP) ## Sweeps through a real SLURM scheduler: a one-node cluster (dev/slurm/cluster.sh; apt-get as root if missing), tests/experiments/test_slurm.py, cluster stopped unless it was up or KEEP=1 (~1.5 min)
	@up=0; dev/slurm/cluster.sh status >/dev/null 2>&1 && up=1; \
	dev/slurm/cluster.sh start && eval "$$(dev/slurm/cluster.sh env)" && \
	LIDARCAM_REQUIRE_SLURM=1 $(PY) -m pytest -m slurm -rA tests/experiments/test_slurm.py; rc=$$?; \
	if [ $$up = 0 ] && [ -z "$(KEEP)" ]; then dev/slurm/cluster.sh stop; fi; exit $$rc

lint: $(STAMP) ## ruff check (~5 s)
	$(VENV)/bin/ruff check .

bench: $(STAMP) ## Time calibrate() per method and the minimal solver's throughput (~1 min; 1.5-2 min on busy cores)
	$(PY) -m experiments bench

PRESET ?=
TRIALS ?= 500
reproduce-paper: $(STAMP) ## Paper's sweeps -> results/paper/ (~2 min; when the store holds the rows and nothing changed, ~5 s of CPU: no redraw); PRESET=paper-matched [TRIALS=500]: -> results/paper-matched/ (~3 min)
ifeq ($(strip $(PRESET)),)
	$(PY) -m experiments reproduce
else
	$(PY) -m experiments matched --preset $(PRESET) --trials $(TRIALS) --compare-trials $(TRIALS)
endif

search-paper: $(STAMP) ## Search the paper's unstated settings (conf/search/paper.yaml), write results/search/ and the preset (~41 min)
	$(PY) -m experiments search --write-preset

explain-paper: $(STAMP) ## Ablations of peng2022 + unstated-setting sweeps, write results/explain/ (~3.5 min)
	$(PY) -m experiments explain

corner-noise: $(STAMP) ## Camera-noise sweeps (joint model over corners and ranges), write results/corner_noise/ (~1 min)
	$(PY) -m experiments corner-noise --trials 25 --boards-trials 25

REAL_DATA ?= ../shared/real-data
real-data: $(STAMP) ## The five public rigs end to end and the paper's real experiment, write results/real/ (REAL_DATA=path; ~0.5-2 min with the stored subset rows: 22 s idle, 113 s on busy cores; ~3-13 min when a library change recomputes them: 173 s, 774 s)
	$(PY) -m experiments real-data --data $(REAL_DATA)

leaderboard: $(STAMP) ## Every registered method on conf/leaderboard/v3.yaml -> results/leaderboard/ (~5 min; FULL=1: full counts; ARGS='methods.plugins=[my_lab.x]')
	$(PY) -m experiments leaderboard $(if $(FULL),--full) $(ARGS)

verify-results: $(STAMP) ## Check every stored trial chunk under results/ parses in full; list reports stale against the code (~3 s)
	$(PY) -m experiments verify results

clean-results: ## Empty the trial stores under results/ (results/*/trials: every row is recomputed on the next run; < 1 s)
	rm -rf results/*/trials

rig-like: $(STAMP) ## Every method on boards 3-8 under rig conditions (conf/preset/rig-like.yaml), write results/rig-like/ (RIG_TRIALS=200; ~1 min)
	$(PY) -m experiments rig-like --trials $(or $(RIG_TRIALS),200)

robustness: $(STAMP) ## Wrong boards, outlier points, mixed pixels (experiment=outliers), write results/outliers/ (~40 s)
	$(PY) -m experiments outliers

plan-check: $(STAMP) ## The capture planner against the simulator (conf/plan/check.yaml), write results/plan/ (~1 min)
	$(PY) -m experiments plan-check

clean: ## Remove the virtual environment and caches (< 1 s)
	rm -rf $(VENV) .pytest_cache .ruff_cache outputs multirun
