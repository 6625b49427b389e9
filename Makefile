# Every target runs `setup` first when needed. See README.md.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
LOGS := logs
REPORTS := generated_reports
# The seed robot's missions (the notes' system) and the servicer's (a 150 kg bus); the
# unbounded mission ends diverged by design and is run by the claims (`expect: diverged`).
MISSIONS := nominal omega_ripple_dt010 omega_ripple_imex omega_ripple_reach \
	servicer_nominal servicer_dt010 servicer_imex

.PHONY: help all setup compile lock runs analyses report claims claims-ci test test-all lint
.PHONY: sweep bench studies
.PHONY: baselines repin tolerances clean slurm-up slurm-down

.DEFAULT_GOAL := all

# Nothing is byte-compiled at install (that took half of set-up); each module is compiled the
# first time a command imports it and kept, so only what runs is compiled, once. A machine that
# sets PYTHONDONTWRITEBYTECODE would instead compile every import of every command again (a
# second per process); the caches written here are .venv's and the project's own.
unexport PYTHONDONTWRITEBYTECODE

## help: list the targets, one line each (from the `## target: …` comments of this file)
help:
	@awk '/^## [a-z-]+: / { sub(/^## /, ""); split($$0, a, ": "); \
		printf "  make %-11s %s\n", a[1], substr($$0, length(a[1]) + 3) }' $(firstword $(MAKEFILE_LIST))

# One process (`python -m pipeline all`): the kernels compiled once, on both cores (a no-op
# once done); the claims (they run what is missing, the sweeps included; each mission,
# analysis and sweep is a stage of its own on stderr); then the reports, which link the
# register. The reports are rendered even when a claim fails, and the command then ends with
# the claims' own code (1: make prints "Error 1"; GNU make itself exits 2 whenever a recipe
# fails, its only code for that).
## all: set-up, compile, missions, analyses, sweeps, claims and every report (generated_reports/index.html)
all: $(STAMP)
	@$(PY) -m pipeline all --claims claims --out $(REPORTS)

# The studies (docs/montecarlo.md, "the decision and the studies"): the claims' Monte Carlos and power studies at their files' full N
# (hours of CPU on a laptop; STUDY_WORKERS, or a cluster: python -m pipeline studies --help),
# one after another with progress, each one's kept records reused and a current one not flown
# again; then the claims and reports as `make all`, which read them from then on. Without
# them `make all` defers the claims that need them (DEFERRED: not PASS, not FAIL). For each
# Monte Carlo that does not show its target, then the least change of each knob every sample
# meets (python -m pipeline search) and each fix flown through the same samples (fixes).
STUDY_WORKERS ?= 2
## studies: the Monte Carlos and power studies at full N, the fix searches and fixes of those not shown, then the claims and reports
studies: $(STAMP)
	@$(PY) -m pipeline studies --claims claims --out $(REPORTS) --workers $(STUDY_WORKERS)

## setup: create .venv and install the pinned versions of constraints.txt
setup: $(STAMP)

# Said as it happens: scripts/setup-venv.sh (uv, installed once per machine into the per-user
# cache folder at the version of UV_VERSION, installs the pinned packages; where uv cannot be
# had, pip does).
UV_VERSION := 0.13.9
$(STAMP): pyproject.toml constraints.txt scripts/setup-venv.sh
	@bash scripts/setup-venv.sh $(PYTHON) $(VENV) $(UV_VERSION) && touch $@

## compile: compile the Numba kernels once, on two cores (make all does it first)
compile: $(STAMP)
	$(PY) -m pipeline compile

# Refresh the pinned versions: a throw-away venv, the ranges of pyproject.toml, pip freeze.
# Deliberate: run `make baselines` after it, and re-pin only with a reason.
## lock: refresh constraints.txt from pyproject.toml's ranges (then: make baselines)
lock:
	rm -rf .venv-lock && $(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --upgrade pip
	.venv-lock/bin/python -m pip install --quiet -e ".[dev,slurm]"
	{ sed -n '/^#/p' constraints.txt; .venv-lock/bin/python -m pip freeze --exclude-editable \
		| grep -v '^-e'; } > constraints.txt.new && mv constraints.txt.new constraints.txt
	rm -rf .venv-lock

# Make's timestamps decide nothing here: each command asks pipeline/provenance whether its
# artefact is current (a log: the simulator's sources, the spec, the robot file and the
# numerical libraries; an analysis: its logs and the analysis' sources; the reports: their
# inputs and templates), says "up to date" and reuses it, or makes it.
## runs: simulate the default missions into logs/<mission>/run.parquet
runs: $(STAMP)
	$(PY) -m pipeline run $(MISSIONS) --out $(LOGS)

# mission:against (empty: analysed alone)
ANALYSES := nominal:omega_ripple_dt010 omega_ripple_imex:omega_ripple_dt010 \
	omega_ripple_reach:omega_ripple_dt010 omega_ripple_dt010: \
	servicer_nominal:servicer_dt010 servicer_imex:servicer_dt010 servicer_dt010:
## analyses: analyse the default missions into generated_reports/<mission>/analysis.json
analyses: runs
	@for pair in $(ANALYSES); do m=$${pair%%:*}; a=$${pair#*:}; \
		$(PY) -m pipeline analyze $(LOGS)/$$m/run.parquet \
			$${a:+--against $(LOGS)/$$a/run.parquet} --out $(REPORTS) || exit $$?; done

## report: render the figures, reports and generated_reports/index.html
report: analyses
	$(PY) -m pipeline report --out $(REPORTS)

## claims: evaluate the claims register (specs/claims.yaml) -> generated_reports/CLAIMS.md
claims: $(STAMP)
	$(PY) -m pipeline claims --claims claims --out $(REPORTS)

# The claim gate of CI: the same claims on the short missions, the studies flown at the small
# N claims_ci.yaml declares (their claims deferred: that N cannot show the target).
## claims-ci: the same claims on the short CI missions -> generated_reports/ci/
claims-ci: $(STAMP)
	$(PY) -m pipeline claims --claims claims_ci --out $(REPORTS)/ci --studies run

# The fast set leaves out what needs SLURM, a browser, a fresh install or a compile into an
# empty cache, and the slow tests (markers in pyproject.toml); test-all, what .ci/run calls,
# runs everything. The kernels are compiled once per session, before the first test
# (tests/conftest.py: the compile stage, a no-op when up to date). pytest's exit code 5 (no
# tests collected, e.g. every one deselected) is not a failure.
FAST := not slow and not slurm and not browser and not install and not compile
PYTEST_RC5 := rc=$$?; if [ $$rc -eq 5 ]; then echo "no tests collected"; rc=0; fi; exit $$rc
## test: run the fast tests (pytest; no SLURM, browser, fresh install, full compile, slow)
test: $(STAMP)
	$(PY) -m pytest -q -m "$(FAST)"; $(PYTEST_RC5)

## test-all: run every test, as CI does (.ci/run; SLURM tests: make slurm-up, or root)
test-all: $(STAMP)
	$(PY) -m pytest -q; $(PYTEST_RC5)

## lint: check the code with ruff
lint: $(STAMP)
	$(PY) -m ruff check pipeline tests

# The default dt sweep (claim C12): nominal, 20 s missions, dt from 0.005 to 0.04 s across
# dt* = 2/μ_max = 0.0156 s -> $(REPORTS)/sweeps/nominal_dt/sweep.parquet. See docs/sweeps.md.
# The bus-inertia sweep (claim C27) runs with the claims (specs/claims.yaml, sweeps.inertia).
SWEEP_DTS := 0.005,0.01,0.015,0.0175,0.02,0.0225,0.025,0.03,0.04
SWEEP_WORKERS ?= 2
## sweep: the default dt sweep on Dask -> generated_reports/sweeps/nominal_dt/
sweep: $(STAMP)
	$(PY) -m pipeline sweep nominal --set mission.dt=$(SWEEP_DTS) --set mission.duration=20 \
		--workers $(SWEEP_WORKERS) --name nominal_dt --logs $(LOGS)/sweeps --out $(REPORTS)/sweeps

## bench: simulator and analysis cost against the Pinocchio floor -> generated_reports/bench.md
bench: $(STAMP)
	$(PY) -m pipeline bench --out $(REPORTS)

# A single-node SLURM on localhost (Debian's munge, slurmctld, slurmd) for the SLURM tests
# (pytest -m slurm) and the sweep throughput of `make bench`; its state in one folder per
# checkout, /tmp/breve-slurm-<hash of the checkout's path> (BREVE_SLURM_DIR), with its own ports.
## slurm-up: start a single-node SLURM on localhost (installs Debian's packages; root)
slurm-up:
	scripts/slurm-local.sh install
	scripts/slurm-local.sh up

## slurm-down: stop the local SLURM that slurm-up started
slurm-down:
	scripts/slurm-local.sh down

## baselines: compare the pinned baseline logs under logs/baselines/ with fresh runs
baselines: $(STAMP)
	$(PY) -m pipeline.claims.baselines check

## repin: re-pin the baseline logs under logs/baselines/ (deliberately, with a reason)
repin: $(STAMP)
	$(PY) -m pipeline.claims.baselines repin

# The baselines' per-column tolerances on another platform, measured (about 90 s here): each
# baseline re-run under the OpenBLAS kernels this CPU runs and one-ulp perturbations of its
# state; docs/reproducibility.md. After a re-pin, with the same commit.
## tolerances: measure the baselines' cross-platform tolerances -> logs/baselines/tolerances.json
tolerances: $(STAMP)
	$(PY) -m pipeline.claims.baselines tolerances

# Compiled kernels: all but the newest cache folder (one per version of pipeline/sim/*.py).
## clean: remove generated logs, reports and all but the newest compiled kernels
clean:
	rm -rf $(REPORTS) $(LOGS)/nominal $(LOGS)/omega_ripple_* $(LOGS)/servicer_* $(LOGS)/short_* \
		$(LOGS)/sweeps
	ls -td pipeline/sim/__pycache__/numba-* 2>/dev/null | tail -n +2 | xargs rm -rf
	rm -f pipeline/sim/__pycache__/*.nbi pipeline/sim/__pycache__/*.nbc
