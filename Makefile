# The two front-door commands (see README.md):
#   make demo   a simulated drive with the default embedded model: latency/memory report, pictures
#               and out/demo/drive.mcap (open it in Foxglove)
#   make test   the whole test suite (Rust and Python, the host and the ECU targets under
#               emulation); .ci/run calls it
# Commands a person runs, never CI: make train (the trained default model), make qat (its int8
# fine-tuning), make fuzz (the libFuzzer campaign), make fuzz-parsers (1.8M generated inputs).
# Everything they need is installed by the targets themselves.

PY_VENV := models/.venv
PY := $(PY_VENV)/bin/python
CARGO ?= cargo

.PHONY: demo test test-rust test-tiers test-python test-paper test-f16-bev test-c lint nostd venv train qat fuzz fuzz-ci \
  fuzz-parsers bench-peers \
  cross-toolchain test-aarch64 test-baremetal test-targets insn-counts

# The demo runs the binary `make test` builds (the same cargo command, so the dependency tree is
# compiled once for both): the test profile, opt-level 3 for ours and tract's engine, the
# dependencies without debug assertions (Cargo.toml).
# `cargo run -p satmap-sim` would resolve features for that one package and compile tract again.
demo:
	$(CARGO) test --workspace --exclude satmap-nostd-check --no-run
	target/debug/satmap-sim drive --out out/demo --mcap out/demo/drive.mcap

# The Python venv (pip, ~5 GB of wheels: network and disk, not CPU) and the cross toolchain
# (Debian packages into a chroot, ~3 GB: network and disk) install in the background while the
# Rust steps compile; their logs are printed after them, and any of them failing fails `test`.
# Then the ECU targets under emulation (test-targets), the paper variant and the Python tests
# (pytest last: its closing line is the run's).
test:
	@mkdir -p out
	@{ $(MAKE) --no-print-directory venv > out/venv.log 2>&1; echo $$? > out/venv.rc; } & \
	  { $(MAKE) --no-print-directory cross-toolchain > out/cross-toolchain.log 2>&1; \
	    echo $$? > out/cross-toolchain.rc; } & \
	  $(MAKE) --no-print-directory lint nostd test-rust test-tiers test-c fuzz-ci; rust=$$?; wait; \
	  echo "--- make venv (run beside the Rust steps):"; cat out/venv.log; \
	  echo "--- make cross-toolchain (run beside the Rust steps):"; cat out/cross-toolchain.log; \
	  test $$rust -eq 0 && test "$$(cat out/venv.rc)" -eq 0 && test "$$(cat out/cross-toolchain.rc)" -eq 0
	$(MAKE) --no-print-directory test-targets test-paper test-f16-bev test-python

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --exclude satmap-nostd-check --all-targets -- -D warnings
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --workspace --exclude satmap-nostd-check --no-deps
	cd fuzz && $(CARGO) fmt -- --check && $(CARGO) clippy --all-targets -- -D warnings

# Links the no_std core into a staticlib with its own panic handler: fails if std sneaks in.
# Built on its own (a workspace-wide build unifies in the host crates' `std` features) and with
# panic=abort (a no_std artifact has no unwinder); see runtime/nostd_check/src/lib.rs.
nostd:
	$(CARGO) rustc -p satmap-nostd-check -- -C panic=abort

test-rust:
	$(CARGO) test --workspace --exclude satmap-nostd-check

# The engine's native passes (each bit for bit against tract's plan) and the demo drive's pinned
# digest once more on the AVX2 + FMA tier of satmap-kernels, forced (SATMAP_KERNEL_TIER), on an
# AVX-512 CPU: every tier gives the same bits, so the default tier's pins hold (the tiers' own
# tests are in test-rust; NEON's run in test-aarch64). ~15 s with test-rust's binaries: the
# engine's test binary is the one the workspace build made (a `-p` build would resolve features
# apart and rebuild tract).
test-tiers:
	@if grep -qw avx512f /proc/cpuinfo; then \
	  echo "SATMAP_KERNEL_TIER=avx2-fma: the engine's passes and the demo digest"; \
	  built=$$($(CARGO) test --workspace --exclude satmap-nostd-check --lib --no-run 2>&1) \
	    || { echo "$$built"; exit 1; }; \
	  engine=$$(echo "$$built" | sed -n 's|.*(\(.*/deps/satmap_engine_tract-[0-9a-f]*\))$$|\1|p' \
	    | head -n 1); \
	  test -x "$$engine" || { echo "test-tiers: no satmap-engine-tract test binary"; exit 1; }; \
	  SATMAP_KERNEL_TIER=avx2-fma "$$engine" && \
	  SATMAP_KERNEL_TIER=avx2-fma $(CARGO) test --workspace --exclude satmap-nostd-check \
	    --test harness_arena -- demo_drive; \
	else echo "test-tiers: skipped, this CPU lacks AVX-512F (the engine's native tests are built where it is)"; fi

# Coverage-guided fuzzing (cargo fuzz, libFuzzer) of the parsers of outside bytes: 8 targets under fuzz/
# (archive, signed bundle, NNEF stage and text, map frame, route pack, manifest, MCAP recording), each
# FUZZ_SECONDS on a corpus kept in target/fuzz-corpus/ (a campaign resumes) seeded from
# fuzz/seeds/; one line per target: execs, edges covered, corpus, crashes. fuzz-ci is CI's
# slice (5 s a target, after a ~2 min cargo-fuzz install and a ~1 min build).
FUZZ_SECONDS ?= 300
fuzz:
	bash fuzz/run.sh $(FUZZ_SECONDS)
fuzz-ci:
	bash fuzz/run.sh 5

# The generated-input campaign (never run in CI; CI runs the same file at 256 cases per parser): 12 parsers x
# FUZZ_CASES inputs (1,800,000 by default) through tests/fuzz_parsers/, one line per parser
# ("inputs run: N ... panics found: 0"), then the total; ~6 min on 2 cores. The test profile, not
# --release: opt-level 3 with debug assertions and overflow checks, which catch more.
# FUZZ_SEED=<u64> repeats a run. See ARCHITECTURE.md "Fuzzing".
FUZZ_CASES ?= 150000
FUZZ_SEED ?= random
fuzz-parsers: SHELL := /bin/bash
fuzz-parsers: .SHELLFLAGS := -o pipefail -c
fuzz-parsers:
	mkdir -p out
	SATMAP_FUZZ_CASES=$(FUZZ_CASES) SATMAP_FUZZ_SEED=$(FUZZ_SEED) \
	  $(CARGO) test --test fuzz_parsers -- --nocapture 2>&1 | tee out/fuzz.log
	@awk 'match($$0, /^fuzz [a-z_]+: inputs run: [0-9]+/) { k++; split(substr($$0, RSTART, RLENGTH), f, ": "); n += f[3] } \
	  match($$0, /panics found: [0-9]+/) { split(substr($$0, RSTART, RLENGTH), f, ": "); p += f[2] } \
	  END { printf "fuzz total: %d parsers, inputs run: %d, panics found: %d\n", k, n, p; \
	  exit (k == 12 && p == 0) ? 0 : 1 }' out/fuzz.log

venv: $(PY_VENV)/.installed

$(PY_VENV)/.installed: models/pyproject.toml
	python3 -m venv $(PY_VENV)
	$(PY_VENV)/bin/pip install --quiet --disable-pip-version-check --no-cache-dir -e 'models[test]'
	touch $@

test-python: venv
	$(PY) -m pytest models -q

# The BEV feature maps stored as f16 (layouts/nano-f16-bev.toml, docs/ecu-integration.md): the
# core's tests built with that layout, so `FeatureStorage::LAYOUT` is f16 and the caller-placed
# regions are cut as halves (`placement`), in a target folder of their own (the layout is a build input;
# sharing target/ would rebuild the workspace crates back and forth). ~1 min on 2 cores. The
# storage's effect on the maps runs in test-rust (both storages in one build: the ECU test
# against the goldens, also under qemu, and the arena replay).
test-f16-bev:
	SATMAP_LAYOUT=layouts/nano-f16-bev.toml CARGO_TARGET_DIR=target/f16-bev \
	  $(CARGO) test -p satmap-core

# The `paper` product variant end to end: export the paper config (seeded weights, ~15 s) into
# models/build/paper, build satmap-sim with its memory layout (SATMAP_LAYOUT=layouts/paper.toml:
# the layout is a build input, so this rebuilds the workspace crates only, and the next build
# without it rebuilds them back) and drive PAPER_FRAMES frames through SatMap in the arena; fails
# when the drive does (a region too small, the arena exhausted, a budget exceeded). In `test`
# after test-rust, so CI builds both layouts. See docs/ecu-integration.md "Memory layout per product variant".
# The binary comes from the same `cargo test --workspace` command as test-rust (an integration
# test of satmap-sim makes cargo build it): `cargo run -p satmap-sim` would resolve dependency
# features for that one package and recompile tract (~8 min of CI).
PAPER_BUNDLE := models/build/paper
PAPER_FRAMES ?= 2
SATMAP_PY_SOURCES := $(shell find models/src/satmap_ref -name '*.py')
test-paper: $(PAPER_BUNDLE)/manifest.sha256
	SATMAP_LAYOUT=layouts/paper.toml $(CARGO) test --workspace --exclude satmap-nostd-check \
	  --no-run --test harness_arena
	target/debug/satmap-sim drive --bundle $(PAPER_BUNDLE) --frames $(PAPER_FRAMES) --quiet

$(PAPER_BUNDLE)/manifest.sha256: $(PY_VENV)/.installed $(SATMAP_PY_SOURCES)
	cd models && .venv/bin/python -m satmap_ref.export --config paper --out build/paper

# Our runtime, onnxruntime and PyTorch eager side by side (never run in CI; 8-10 min on 2026-12-05): every stage
# of test, nano and paper on each bundle's recorded inputs at 1 and 2 threads, FLOPs, the
# machine's matmul peak, max RSS per engine; writes docs/perf.md and docs/perf.json. See
# models/src/satmap_ref/peers.py. PEERS_FLAGS=--rounds 1 for a quick look.
# Each bundle also runs in its compiled NNEF form (`<bundle>.satmap`, the form the runtime ships;
# the default's is committed, nano's and paper's are compiled here, paper against its layout).
# int8 (`test`, `nano`): ours on the W8A8 bundle (`test`'s committed, `nano`'s compiled and
# calibrated here) against onnxruntime on the stages `satmap_ref.ort_int8` quantises
# (quantize_static, QDQ) over the frames our calibration uses: training-split worlds 1000..1004,
# 8 frames each (exported here; the one-drive validation and test splits export-dataset insists
# on are not read; `nano` takes `test`'s inputs, `paper` does not and has no int8 column).
NANO_BUNDLE := models/build/nano
CALIBRATION_FRAMES := models/build/calibration-frames
PEERS_FLAGS ?= --rounds 3 --repeats 5
bench-peers: $(NANO_BUNDLE)/manifest.sha256 $(PAPER_BUNDLE)/manifest.sha256
	$(CARGO) test --workspace --exclude satmap-nostd-check --no-run
	target/debug/satmap-sim compile --bundle $(NANO_BUNDLE) --out $(NANO_BUNDLE).satmap
	target/debug/satmap-sim compile --bundle $(PAPER_BUNDLE) --out $(PAPER_BUNDLE).satmap \
	  --layout layouts/paper.toml
	target/debug/satmap-sim export-dataset --out $(CALIBRATION_FRAMES) --train-seeds 1000..1004 \
	  --val-seeds 2000..2001 --test-seeds 3000..3001 --frames 8 --quiet
	target/debug/satmap-sim compile --bundle $(NANO_BUNDLE) --precision int8 \
	  --out $(NANO_BUNDLE)-int8.satmap
	target/debug/satmap-sim compile --bundle $(NANO_BUNDLE)-int8.satmap --precision int8 \
	  --calibrate 1000..1004 --calibration-frames 8 --out $(NANO_BUNDLE)-w8a8.satmap
	cd models && .venv/bin/python -m satmap_ref.ort_int8 --bundle bundles/test \
	  --data build/calibration-frames --out build/test-ort-int8
	cd models && .venv/bin/python -m satmap_ref.ort_int8 --bundle build/nano \
	  --data build/calibration-frames --out build/nano-ort-int8
	cd models && .venv/bin/python -m satmap_ref.peers --sim ../target/debug/satmap-sim \
	  --bundle test=bundles/test --bundle nano=build/nano --bundle paper=build/paper \
	  --int8 test=bundles/test-w8a8.satmap:build/test-ort-int8 \
	  --int8 nano=build/nano-w8a8.satmap:build/nano-ort-int8 \
	  --threads 1 2 $(PEERS_FLAGS) --out ../docs/perf

$(NANO_BUNDLE)/manifest.sha256: $(PY_VENV)/.installed $(SATMAP_PY_SOURCES)
	cd models && .venv/bin/python -m satmap_ref.export --config nano --out build/nano

# The C API from C: builds the static library, compiles examples/c/replay.c with the system C
# compiler (warnings are errors) and replays the committed scenario over static caller-owned
# regions, natively (digests must equal the Rust run's, examples/c/expected-<family>.txt, checked by
# tests/integration/c_api.rs; every CRC check and every bit flip of a frame caught), then the first two
# frames again under valgrind (any memory error or leak fails; see replay.c on why digests are
# not compared there). Then once more the way an ECU creates it: a key pair made, a copy of the
# bundle signed, `satmap_create_trusted` verifying the signature (and refusing another pin).
# The static library `cargo test` builds for the workspace (crate-type staticlib): the same
# command as test-rust, so nothing is rebuilt; `cargo build -p satmap-capi` alone would unify
# other dependency features and recompile tract (~7 min).
CAPI_LIB := target/debug/deps/libsatmap_capi.a
C_REPLAY := target/c/replay
# The replay compares with examples/c/expected-<family>.txt, the family named by the library
# itself (satmap_kernel_family(), the one rule in runtime/engine_tract/src/kernel_family.rs).
C_REPLAY_ARGS := models/bundles/test.satmap models/calibration/nuscenes_like.toml examples/c/scenario.bin \
  examples/c
test-c:
	$(CARGO) test --workspace --exclude satmap-nostd-check --no-run
	mkdir -p target/c
	$(CC) -std=c11 -Wall -Wextra -Werror -g -O1 -I runtime/capi/include examples/c/replay.c \
	  $(CAPI_LIB) -lgcc_s -lutil -lrt -lpthread -lm -ldl -lc -o $(C_REPLAY)
	$(C_REPLAY) $(C_REPLAY_ARGS)
	rm -rf target/c/signed && mkdir -p target/c/signed
	target/debug/satmap-sim keygen --out-dir target/c/signed
	cp models/bundles/test.satmap target/c/signed/
	target/debug/satmap-sim sign-bundle --key target/c/signed/bundle-signing.key \
	  target/c/signed/test.satmap
	$(C_REPLAY) target/c/signed/test.satmap $(wordlist 2,4,$(C_REPLAY_ARGS)) \
	  target/c/signed/bundle-signing.pub
	command -v valgrind >/dev/null || flock /tmp/satmap-apt.lock \
	  sh -c 'apt-get update -qq && apt-get install -y -qq valgrind'  # the lock: targets/toolchain.sh
	valgrind --error-exitcode=1 --leak-check=full --errors-for-leak-kinds=definite,indirect \
	  --suppressions=examples/c/valgrind.supp --quiet $(C_REPLAY) $(C_REPLAY_ARGS) memcheck

# Reproduces the trained default model (never run in CI; ~80 min on this 2-core machine):
# the synthetic dataset (200 drives x 24 frames, split by world seed), the camera-only and the
# camera + satellite model trained side by side with the same budget (one thread each), the
# held-out report, then the committed weights, bundle and goldens. Resumable: run it again after
# an interruption and each step continues from what is on disk.
DATA ?= out/dataset
RUNS ?= out/runs
TRAIN_FLAGS ?= --steps 2000 --batch 4 --lr 6e-4 --warmup 150 --threads 1
train: venv
	$(CARGO) build --release -p satmap-sim
	./target/release/satmap-sim export-dataset --out $(DATA)
	$(PY) -m satmap_ref.train --data $(DATA) --mode camera --out $(RUNS)/camera $(TRAIN_FLAGS) & \
	  $(PY) -m satmap_ref.train --data $(DATA) --mode sat --out $(RUNS)/sat $(TRAIN_FLAGS); \
	  s=$$?; wait $$! && test $$s -eq 0
	$(PY) -m satmap_ref.train.report --data $(DATA) --split test --sim target/release/satmap-sim \
	  --run camera=$(RUNS)/camera/weights.safetensors --run sat=$(RUNS)/sat/weights.safetensors \
	  --log camera=$(RUNS)/camera/log.jsonl --log sat=$(RUNS)/sat/log.jsonl --out docs/training
	cp $(RUNS)/sat/weights.safetensors models/weights/test_sat.safetensors
	cp $(RUNS)/camera/weights.safetensors models/weights/test_camera.safetensors
	$(PY) -m satmap_ref.golden --take-input $(DATA)

# Quantisation-aware fine-tuning of the trained `test` weights for int8 (never run in CI; ~9 min
# on this 2-core machine; docs/int8.md, "The error: ..."): the training split's
# worlds 1000..1039 (24 frames each), 400 updates distilling the f32 model into its int8-rounded
# self, the weights snapped to their int8 grid (committed: models/weights/test_sat_qat.safetensors),
# then their W8A32 and W8A8 bundles (calibrated as the committed one). Resumable: the export
# skips finished drives, the fine-tuning continues from its checkpoint (exit 3 when it stopped
# at a time limit, so nothing after it runs on stale weights).
QAT_DATA ?= out/qat-data
QAT_RUN ?= out/qat-run
QAT_FLAGS ?= --steps 400 --batch 4 --lr 1e-4 --warmup 20 --threads 2
qat: venv
	$(CARGO) test --workspace --exclude satmap-nostd-check --no-run
	target/debug/satmap-sim export-dataset --out $(QAT_DATA) \
	  --train-seeds 1000..1040 --val-seeds 2000..2001 --test-seeds 3000..3001 --quiet
	cd models && .venv/bin/python -m satmap_ref.train.qat --data $(abspath $(QAT_DATA)) \
	  --weights weights/test_sat.safetensors --out $(abspath $(QAT_RUN)) $(QAT_FLAGS)
	cp $(QAT_RUN)/weights.safetensors models/weights/test_sat_qat.safetensors
	cd models && .venv/bin/python -m satmap_ref.export --config test --out build/test-qat \
	  --weights weights/test_sat_qat.safetensors
	target/debug/satmap-sim compile --bundle models/build/test-qat --precision int8 \
	  --out models/build/test-qat-int8.satmap
	target/debug/satmap-sim compile --bundle models/build/test-qat-int8.satmap --precision int8 \
	  --calibrate 1000..1004 --calibration-frames 8 --out models/build/test-qat-w8a8.satmap

# The ECU's processors, under emulation (docs/targets.md; targets/README.md). The toolchain comes
# from Debian's packages only: a trixie chroot with Rust 1.96, aarch64's std, the std sources
# for -Z build-std, the aarch64 GCC and qemu, cached outside the repository
# (/var/cache/satmap-cross; idempotent, ~4 min the first time).
cross-toolchain:
	bash targets/toolchain.sh

# aarch64-unknown-linux-gnu, the application core (Cortex-A76 under qemu-aarch64): the ECU tests
# and the C API's, then the C example cross-compiled and replayed. The determinism test takes
# AARCH64_DETERMINISM_STEPS steps in each of two processes (200 on the host; a slice here, ~4 s a
# step under emulation; `make test-aarch64 AARCH64_DETERMINISM_STEPS=200` runs the full count).
AARCH64_DETERMINISM_STEPS ?= 24
test-aarch64: cross-toolchain
	SATMAP_DETERMINISM_STEPS=$(AARCH64_DETERMINISM_STEPS) bash targets/aarch64.sh

# aarch64-unknown-none and thumbv7em-none-eabihf, the safety core: the core check's images under
# qemu-system, digests equal to the host's, .text and static RAM per image. Needs the host's
# satmap-baremetal (built by test-rust's cargo command) for the host's line.
test-baremetal: cross-toolchain
	$(CARGO) test --workspace --exclude satmap-nostd-check --no-run
	bash targets/baremetal.sh

test-targets: test-aarch64 test-baremetal

# Instructions retired per stage on the application core (docs/perf.md, "On ARM"): our engine's
# f32/f16/int8 bundles and onnxruntime's aarch64 wheel, under qemu-aarch64 rebuilt with TCG
# plugins from Debian's qemu source (once, a few minutes). A person's command, not a CI step: about half an hour (each stage emulated in two processes per column).
insn-counts: cross-toolchain
	SATMAP_ORT_COUNTS=1 bash targets/insn_counts.sh
