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
SOURCES := $(shell find pipeline -name '*.py' -o -name '*.j2') $(wildcard specs/*.yaml) $(wildcard specs/robots/*)

.PHONY: all setup lock runs analyses report claims claims-ci test lint sweep bench baselines repin clean \
	slurm-up slurm-down

# The claims first (they run what is missing, the sweeps included), then the reports, which
# link the register; the reports are rendered even when a claim fails, and the recipe then
# ends with the claims' own code (1: make prints "Error 1"; GNU make itself exits 2 whenever a
# recipe fails, its only code for that).
all: $(STAMP)
	@$(PY) -m pipeline claims --claims specs/claims.yaml --out $(REPORTS); rc=$$?; \
	$(MAKE) --no-print-directory report || exit $$?; exit $$rc

setup: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e ".[dev,slurm]"
	touch $@

# Refresh the pinned versions: a throw-away venv, the ranges of pyproject.toml, pip freeze.
# Deliberate: run `make baselines` after it, and re-pin only with a reason.
lock:
	rm -rf .venv-lock && $(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --upgrade pip
	.venv-lock/bin/python -m pip install --quiet -e ".[dev,slurm]"
	{ sed -n '/^#/p' constraints.txt; .venv-lock/bin/python -m pip freeze --exclude-editable \
		| grep -v '^-e'; } > constraints.txt.new && mv constraints.txt.new constraints.txt
	rm -rf .venv-lock

$(LOGS)/%/run.parquet: $(SOURCES) | $(STAMP)
	$(PY) -m pipeline run $* --out $(LOGS)

runs: $(foreach m,$(MISSIONS),$(LOGS)/$(m)/run.parquet)

# An analysis is redone when its logs are newer (and a log when the sources are); `claims`
# writes the same records, so after it these are up to date.
analyses: $(foreach m,$(MISSIONS),$(REPORTS)/$(m)/analysis.json)

$(REPORTS)/nominal/analysis.json $(REPORTS)/omega_ripple_imex/analysis.json \
		$(REPORTS)/omega_ripple_reach/analysis.json: \
		$(REPORTS)/%/analysis.json: $(LOGS)/%/run.parquet $(LOGS)/omega_ripple_dt010/run.parquet
	$(PY) -m pipeline analyze $< --against $(LOGS)/omega_ripple_dt010/run.parquet --out $(REPORTS)

$(REPORTS)/servicer_nominal/analysis.json $(REPORTS)/servicer_imex/analysis.json: \
		$(REPORTS)/%/analysis.json: $(LOGS)/%/run.parquet $(LOGS)/servicer_dt010/run.parquet
	$(PY) -m pipeline analyze $< --against $(LOGS)/servicer_dt010/run.parquet --out $(REPORTS)

$(REPORTS)/omega_ripple_dt010/analysis.json $(REPORTS)/servicer_dt010/analysis.json: \
		$(REPORTS)/%/analysis.json: $(LOGS)/%/run.parquet
	$(PY) -m pipeline analyze $< --out $(REPORTS)

report: analyses
	$(PY) -m pipeline report --out $(REPORTS)

claims: $(STAMP)
	$(PY) -m pipeline claims --claims specs/claims.yaml --out $(REPORTS)

# The claim gate of CI: the same claims on the short missions.
claims-ci: $(STAMP)
	$(PY) -m pipeline claims --claims specs/claims_ci.yaml --out $(REPORTS)/ci

test: $(STAMP)
	$(PY) -m pytest -q; rc=$$?; if [ $$rc -eq 5 ]; then echo "no tests collected"; rc=0; fi; exit $$rc

lint: $(STAMP)
	$(PY) -m ruff check pipeline tests

# The default dt sweep (claim C12): nominal, 20 s missions, dt from 0.005 to 0.04 s across
# dt* = 2/μ_max = 0.0156 s -> $(REPORTS)/sweeps/nominal_dt/sweep.parquet. See docs/sweeps.md.
# The bus-inertia sweep (claim C27) runs with the claims (specs/claims.yaml, sweeps.inertia).
SWEEP_DTS := 0.005,0.01,0.015,0.0175,0.02,0.0225,0.025,0.03,0.04
SWEEP_WORKERS ?= 2
sweep: $(STAMP)
	$(PY) -m pipeline sweep nominal --set mission.dt=$(SWEEP_DTS) --set mission.duration=20 \
		--workers $(SWEEP_WORKERS) --name nominal_dt --logs $(LOGS)/sweeps --out $(REPORTS)/sweeps

bench: $(STAMP)
	$(PY) -m pipeline bench --out $(REPORTS)

# A single-node SLURM on localhost (Debian's munge, slurmctld, slurmd; state in /tmp/breve-slurm)
# for the SLURM tests (pytest -m slurm) and the sweep throughput of `make bench`.
slurm-up:
	scripts/slurm-local.sh install
	scripts/slurm-local.sh up

slurm-down:
	scripts/slurm-local.sh down

baselines: $(STAMP)
	$(PY) -m pipeline.reports.baselines check

repin: $(STAMP)
	$(PY) -m pipeline.reports.baselines repin

# Compiled kernels: all but the newest cache folder (one per version of pipeline/sim/*.py).
clean:
	rm -rf $(REPORTS) $(LOGS)/nominal $(LOGS)/omega_ripple_* $(LOGS)/servicer_* $(LOGS)/short_* \
		$(LOGS)/sweeps
	ls -td pipeline/sim/__pycache__/numba-* 2>/dev/null | tail -n +2 | xargs rm -rf
	rm -f pipeline/sim/__pycache__/*.nbi pipeline/sim/__pycache__/*.nbc
