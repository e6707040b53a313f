# The two commands (see README):  make demo   and   make test
# Both create .venv/ at the repo root from the pinned constraints when it is missing.
# make docs builds the documentation site into site/ (warnings are errors).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test lint docs bench study clean-venv

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	PIP_CONSTRAINT=$(CURDIR)/constraints.txt $(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[dev,docs]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/idtool demo --force

# lint-imports: the import layers and contracts of [tool.importlinter] in pyproject.toml
# (docs/architecture.md, "Layers").
lint: $(STAMP)
	$(BIN)/ruff check idtool tests benchmarks
	$(BIN)/ruff format --check idtool tests benchmarks
	$(BIN)/mypy
	$(BIN)/lint-imports --no-cache

# -m "not study": the tests marked study (recovery, coverage and convergence studies on
# simulated benches, pyproject.toml's markers) run in make study instead
test: lint
	MPLBACKEND=Agg $(BIN)/python -m pytest -n 2 --dist loadfile --durations=30 -m "not study"

# The site from docs/ and the docstrings (mkdocs.yml); --strict: any warning (a broken
# link, a docstring mkdocstrings cannot parse, an example importing idtool._*) fails it.
# Offline: nothing is fetched at build time. A few seconds.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_curve.py
	$(BIN)/python benchmarks/bench_trig.py
	$(BIN)/python benchmarks/bench_fit.py
	$(BIN)/python benchmarks/bench_sample.py
	$(BIN)/python benchmarks/bench_first_result.py
	$(BIN)/python benchmarks/bench_read.py

# The defaults on every departure kind of the simulator, 3 seeds each (8 min on 2 cores,
# plus up to 10 per fading-horn bench): run it before closing an issue that touches the
# fit, the likelihood or the sampler, and quote its table (benchmarks/study_departures.py).
# Then the coverage test on all 3 seeds per kind, with the rates that `make test` (one
# seed per kind) leaves to it (tests/test_coverage.py; about 7 min on one core).
# Last, the tests marked study, which make test leaves out (about 8 min on 2 cores).
study: $(STAMP)
	$(BIN)/python benchmarks/study_departures.py --seeds 3
	IDTOOL_COVERAGE_SEEDS=3 MPLBACKEND=Agg $(BIN)/python -m pytest tests/test_coverage.py -s
	MPLBACKEND=Agg $(BIN)/python -m pytest -n 2 --dist loadfile --durations=30 -m study

clean-venv:
	rm -rf $(VENV)
