#!/usr/bin/env bash
# The application core, aarch64-unknown-linux-gnu, under user-mode emulation (qemu-aarch64 with
# the CPU of targets/cross.env): the ECU tests (tests/ecu: the compiled f32/f16/int8 bundles
# against the goldens, determinism within and across processes, 1 vs 2 threads, dropout, the
# LUT, the C-API scenario's digests for this kernel family), the kernels' tier tests (the NEON
# tier against the generic one, bit for bit) and the C API's own tests, then the
# C example cross-compiled with aarch64-linux-gnu-gcc and replayed (CRC checks, bit flips,
# digests against examples/c/expected-<family>.txt). Run by `make test-aarch64`.
#
# SATMAP_DETERMINISM_STEPS (default 200) sets the determinism test's step count; `make test`
# passes a slice (see the Makefile).
set -euo pipefail
cd "$(dirname "$0")/.."
CROSS=targets/in-chroot.sh
TARGET=aarch64-unknown-linux-gnu
OUT=target/cross/$TARGET/debug
mkdir -p out

echo "--- aarch64: build (the ECU build of the runtime, the kernels, the C API, the ECU tests)"
$CROSS cargo test --target $TARGET -p satmap-ecu-tests -p satmap-kernels -p satmap-capi --no-run

echo "--- aarch64: tests under emulation"
# The same cargo command runs them (cargo's runner is the emulator, targets/cross.env).
$CROSS cargo test --target $TARGET -p satmap-ecu-tests -p satmap-kernels -p satmap-capi 2>&1 | tee out/aarch64-tests.log
# The NEON tier's tests must have run here, not been ignored (tests/tiers.rs checks the cfg).
neon=$(grep -c '^test aarch64_neon::.* ok$' out/aarch64-tests.log || true)
if [[ "$neon" -ne 3 ]]; then
  echo "aarch64: the NEON tier's 3 tests did not all run and pass ($neon)" >&2
  exit 1
fi
# And the integer products' dot-product tier (sdot) against the portable reference: the linear
# product's 4 tests and the channel-first (convolution) product's 3 (tests/qgemm_tiers.rs).
sdot=$(grep -c '^test aarch64_dotprod::.* ok$' out/aarch64-tests.log || true)
if [[ "$sdot" -ne 7 ]]; then
  echo "aarch64: the dotprod integer tier's 7 tests did not all run and pass ($sdot)" >&2
  exit 1
fi
passed=$(awk '/^test result:/ { for (i = 1; i <= NF; i++) if ($i == "passed;") n += $(i - 1) } END { print n + 0 }' out/aarch64-tests.log)

echo "--- aarch64: the C example, cross-compiled and replayed"
mkdir -p target/cross/c
$CROSS aarch64-linux-gnu-gcc -std=c11 -Wall -Wextra -Werror -g -O1 -I runtime/capi/include \
  examples/c/replay.c $OUT/deps/libsatmap_capi.a -lgcc_s -lutil -lrt -lpthread -lm -ldl -lc \
  -o target/cross/c/replay
$CROSS bash -c 'qemu-aarch64 -cpu "$SATMAP_QEMU_CPU" -L /usr/aarch64-linux-gnu target/cross/c/replay \
  models/bundles/test.satmap models/calibration/nuscenes_like.toml examples/c/scenario.bin examples/c' \
  | tee out/aarch64-c-example.log
cpu=$($CROSS bash -c 'echo "$SATMAP_QEMU_CPU"')
family=$(grep -m1 -o 'kernel family [a-z0-9-]*' out/aarch64-c-example.log | cut -d' ' -f3 || true)
if [[ "$passed" -eq 0 ]]; then
  echo "aarch64: no test ran" >&2
  exit 1
fi
echo "aarch64 ($cpu under qemu-aarch64, kernel family ${family:-?}): $passed tests passed; C example replayed, digests equal"
