# inkopt: `make demo` and `make test` work on a fresh machine (Python >= 3.10, a Rust toolchain, network to PyPI
# and crates.io). Both set up .venv/ with inkopt installed (the Rust core is compiled in release mode).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.inkopt-installed
RUST_SOURCES := $(wildcard Cargo.toml crates/*/Cargo.toml) $(shell find crates -name '*.rs')
DEMO_OUT ?= demo-out

.PHONY: setup demo test lint test-slow bench clean

setup: $(STAMP)

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): $(PY) pyproject.toml $(RUST_SOURCES)
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/inkopt demo --out $(DEMO_OUT)

test: $(STAMP) lint
	cargo test --release -p inkopt-core
	$(PY) -m pytest -q

# ruff (lint and format) for Python, rustfmt and clippy for Rust; `make test` runs it first
lint: $(STAMP)
	$(VENV)/bin/ruff check python tests bench experiments docs
	$(VENV)/bin/ruff format --check python tests bench experiments docs
	cargo fmt --all -- --check
	cargo clippy --release --workspace --all-targets --quiet -- -D warnings

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

bench: $(STAMP)
	$(PY) bench/bench_render.py

clean:
	rm -rf $(VENV) target $(DEMO_OUT)
