# The README's Quick start: `make demo` and `make test`. Everything else is for developers.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.deps-stamp
BUILD_STAMP := $(VENV)/.build-stamp
DOCS_STAMP := $(VENV)/.docs-stamp
RUST_SOURCES := $(shell find crates -name '*.rs' -o -name Cargo.toml) Cargo.toml pyproject.toml
# The requirements pyproject.toml declares, shell-quoted: $(call requirements) for the package's
# own, $(call requirements,EXTRA) for an extra's. pyproject.toml is their one source.
requirements = $(shell $(PYTHON) -c 'import shlex, sys, tomllib; p = tomllib.load(open("pyproject.toml", "rb"))["project"]; \
	print(shlex.join(p["optional-dependencies"][sys.argv[1]] if sys.argv[1] else p["dependencies"]))' '$(1)')

.PHONY: demo test test-rust test-python test-all bench build fmt clean docs test-viewer wheel test-wheel generate fuzz mutants

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null || { echo "error: $(PYTHON) not found (set PYTHON=...)"; exit 1; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet "maturin>=1.5,<2.0" $(call requirements) $(call requirements,test)
# The optional mesher (extra `mesh`), so that `make test` covers sf.tetrahedralize; skipped without it.
	$(PY) -m pip install --quiet $(call requirements,mesh) || echo "warning: pytetwild not installed: the sf.tetrahedralize tests will be skipped"
# Dask, pyarrow and zarr (extra `cluster`), so that `make test` covers sf.sweep.
	$(PY) -m pip install --quiet $(call requirements,cluster)
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

test-all: build wheel $(DOCS_STAMP)
	cargo test --release -p sorofem-core -- --include-ignored
	$(PY) -m pytest -q -m ""

# An abi3 wheel (one for CPython >= 3.11) of the release build into dist/; it installs without
# Rust. It reuses the release build of `make build` (same profile, same target/).
wheel: $(STAMP)
	rm -f dist/sorofem-*.whl
	VIRTUAL_ENV=$(abspath $(VENV)) PATH=$(abspath $(VENV))/bin:$$PATH $(VENV)/bin/maturin build --release --out dist --quiet

# Installs that wheel into a fresh virtual environment with no Rust toolchain on PATH and runs
# examples/scenes/cantilever.toml with its `sorofem` command (tests/test_packaging.py, marker `wheel`).
test-wheel: build wheel
	$(PY) -m pytest -q -m wheel tests/test_packaging.py

bench: build
	$(PY) -m pip install --quiet $(call requirements,bench)
	$(PY) benchmarks/run.py --write BENCHMARKS.md
	$(PY) -m pytest -q -m bench

# The documentation site (mkdocs.yml, docs/) into site/; warnings are errors. Not part of `test`.
# tests/test_docs_site.py (marker `docs`) builds it once more and reads every page.
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(PY) -m pip install --quiet $(call requirements,docs)
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(VENV)/bin/mkdocs build --strict --quiet
	$(PY) -m pytest -q -m docs tests/test_docs_site.py

# The browser viewer (optional extra) and, when Debian's chromium is installed, a real-browser test.
test-viewer: build
	$(PY) -m pip install --quiet $(call requirements,viewer) "playwright>=1.40"
	SOROFEM_BROWSER_TEST=1 $(PY) -m pytest -q tests/test_viewer.py -rs

# The mesh-reader fuzz target (tests/fuzz_mesh_readers.py): many random and damaged mesh files,
# new ones on every run (Hypothesis's "fuzz" profile). Not part of `test`. FUZZ_EXAMPLES=N.
FUZZ_EXAMPLES ?= 20000
fuzz: build
	$(PY) tests/fuzz_mesh_readers.py --examples $(FUZZ_EXAMPLES)

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

# The copies generated from the scene spec (docs/scene.schema.json, README.md's key table, the
# sorofem.scene docstring); the tests fail when they are stale.
generate: build
	$(PY) -m sorofem.scene.generate

clean:
	rm -rf target $(VENV) results dist
