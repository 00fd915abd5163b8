# The README's Quick start: `make demo` and `make test`. Everything else is for developers.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.deps-stamp
BUILD_STAMP := $(VENV)/.build-stamp
DOCS_STAMP := $(VENV)/.docs-stamp
RUST_SOURCES := $(shell find crates -name '*.rs' -o -name Cargo.toml) Cargo.toml pyproject.toml

.PHONY: demo test test-rust test-python test-all bench build fmt clean docs test-viewer mutants

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null || { echo "error: $(PYTHON) not found (set PYTHON=...)"; exit 1; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet "maturin>=1.5,<2.0" "numpy>=1.24" "scipy>=1.10" "meshio>=5.3" "matplotlib>=3.7" "pytest>=7" "jsonschema>=4"
# The optional mesher (extra `mesh`), so that `make test` covers sf.tetrahedralize; skipped without it.
	$(PY) -m pip install --quiet "pytetwild>=0.2.3,<0.3" || echo "warning: pytetwild not installed: the sf.tetrahedralize tests will be skipped"
	touch $(STAMP)

$(BUILD_STAMP): $(STAMP) $(RUST_SOURCES)
	VIRTUAL_ENV=$(abspath $(VENV)) PATH=$(abspath $(VENV))/bin:$$PATH $(VENV)/bin/maturin develop --release --quiet
	touch $(BUILD_STAMP)

build: $(BUILD_STAMP)

demo: build
	$(PY) examples/01_cantilever_gravity.py --out results/demo

test-rust:
	cargo test --release -p sorofem-core

test-python: build
	$(PY) -m pytest -q

test: test-rust test-python

test-all: build
	cargo test --release -p sorofem-core -- --include-ignored
	$(PY) -m pytest -q -m ""

bench: build
	$(PY) -m pip install --quiet "scikit-fem>=10"
	$(PY) benchmarks/run.py --write BENCHMARKS.md
	$(PY) -m pytest -q -m bench

# The documentation site (mkdocs.yml, docs/) into site/; warnings are errors. Not part of `test`.
$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install --quiet "mkdocs>=1.5" "mkdocstrings[python]>=0.24"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(VENV)/bin/mkdocs build --strict --quiet

# The browser viewer (optional extra) and, when Debian's chromium is installed, a real-browser test.
test-viewer: build
	$(PY) -m pip install --quiet "viser>=1.0" "playwright>=1.40"
	SOROFEM_BROWSER_TEST=1 $(PY) -m pytest -q tests/test_viewer.py -rs

# Mutation testing (docs/testing.md), not part of `test` or CI: every mutant rebuilds the core and
# reruns its tests, so the whole run takes many hours on 2 cores. Narrow it with, e.g.,
# `make mutants MUTANT_FILES=crates/sorofem-core/src/energy/loads.rs MUTANT_PYTHON=`. Results:
# mutants.out/ (cargo-mutants: caught.txt, missed.txt, ...) and `.venv/bin/mutmut results`.
MUTANT_FILES ?= crates/sorofem-core/src/material/*.rs crates/sorofem-core/src/energy/*.rs
MUTANT_PYTHON ?= python/sorofem/cables.py
MUTANT_PYTHON_TESTS ?= tests/test_cables.py tests/test_physics_cables.py
# e.g. --copy-target=true to reuse an existing target/debug instead of building from scratch.
CARGO_MUTANTS_ARGS ?=
mutants: build
	command -v cargo-mutants >/dev/null || cargo install --locked cargo-mutants
	-cargo mutants -p sorofem-core $(foreach f,$(MUTANT_FILES),--file '$(f)') $(CARGO_MUTANTS_ARGS)
	$(PY) -m pip install --quiet "mutmut>=2.5,<3"
	-if [ -n "$(MUTANT_PYTHON)" ]; then \
		$(VENV)/bin/mutmut run --paths-to-mutate '$(MUTANT_PYTHON)' --disable-mutation-types string,fstring \
			--runner '$(abspath $(PY)) -m pytest -x -q -p no:cacheprovider $(MUTANT_PYTHON_TESTS)'; \
		$(VENV)/bin/mutmut results; \
	fi

fmt:
	cargo fmt --all

clean:
	rm -rf target $(VENV) results
