# The two front-door commands (see README.md):
#   make demo   a simulated drive with the default embedded model: latency/memory report + picture
#   make test   the whole test suite (Rust and Python); .ci/run calls it
# Everything they need is installed by the targets themselves.

PY_VENV := models/.venv
PY := $(PY_VENV)/bin/python
CARGO ?= cargo

.PHONY: demo test test-rust test-python lint nostd venv

demo:
	$(CARGO) run --release -p satmap-sim -- drive --out out/demo

test: lint nostd test-rust test-python

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

# Links the no_std core into a staticlib with its own panic handler: fails if std sneaks in.
nostd:
	$(CARGO) build -p satmap-nostd-check

test-rust:
	$(CARGO) test --workspace

venv: $(PY_VENV)/.installed

$(PY_VENV)/.installed: models/pyproject.toml
	python3 -m venv $(PY_VENV)
	$(PY_VENV)/bin/pip install --quiet --disable-pip-version-check -e 'models[test]'
	touch $@

test-python: venv
	$(PY) -m pytest models -q
