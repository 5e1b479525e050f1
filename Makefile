# The two front-door commands (see README.md):
#   make demo   a simulated drive with the default embedded model: latency/memory report + picture
#   make test   the whole test suite (Rust and Python); .ci/run calls it
# Everything they need is installed by the targets themselves.

PY_VENV := models/.venv
PY := $(PY_VENV)/bin/python
CARGO ?= cargo

.PHONY: demo test test-rust test-python lint nostd venv

demo:
	$(CARGO) run -p satmap-sim -- drive --out out/demo

test: lint nostd test-rust test-python

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --exclude satmap-nostd-check --all-targets -- -D warnings

# Links the no_std core into a staticlib with its own panic handler: fails if std sneaks in.
# Built on its own (a workspace-wide build unifies in the host crates' `std` features) and with
# panic=abort (a no_std artifact has no unwinder); see runtime/nostd_check/src/lib.rs.
nostd:
	$(CARGO) rustc -p satmap-nostd-check -- -C panic=abort

test-rust:
	$(CARGO) test --workspace --exclude satmap-nostd-check

venv: $(PY_VENV)/.installed

$(PY_VENV)/.installed: models/pyproject.toml
	python3 -m venv $(PY_VENV)
	$(PY_VENV)/bin/pip install --quiet --disable-pip-version-check -e 'models[test]'
	touch $@

test-python: venv
	$(PY) -m pytest models -q
