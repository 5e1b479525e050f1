#!/usr/bin/env bash
# The safety core, bare metal: the core check (runtime/core_check: calibration and GKT table,
# native gather-sum, CAN-bus vector, frame checks, decode, map-frame wire and CRC, route pack
# parse, crop and tile decode, on golden frame 0) built with -Z build-std=core,alloc for
# aarch64-unknown-none and thumbv7em-none-eabihf, run under qemu-system (virt / Cortex-A53 and
# MPS2-AN386 / Cortex-M4F) with semihosting: each image prints its digests against the host's
# and exits with the comparison's status. Then code size (.text) and static RAM per image.
# Run by `make test-baremetal`.
set -euo pipefail
cd "$(dirname "$0")/.."
CROSS=targets/in-chroot.sh
mkdir -p out
: > out/baremetal.log

# qemu-system runs an image until it exits through semihosting; a hung image is stopped.
QEMU_COMMON="-nographic -monitor none -serial none -semihosting-config enable=on,target=native"
# `-nic none` on virt: otherwise it looks for a network boot ROM that is only a Recommends.
declare -A MACHINE=(
  [aarch64-unknown-none]="qemu-system-aarch64 -M virt -cpu cortex-a53 -m 128M -nic none"
  [thumbv7em-none-eabihf]="qemu-system-arm -M mps2-an386 -cpu cortex-m4"
)
for target in aarch64-unknown-none thumbv7em-none-eabihf; do
  echo "--- bare metal: $target"
  $CROSS env RUSTC_BOOTSTRAP=1 cargo build --release -p satmap-baremetal --target "$target" \
    -Z build-std=core,alloc
  image=target/cross/$target/release/satmap-baremetal
  # shellcheck disable=SC2086
  $CROSS timeout 600 ${MACHINE[$target]} $QEMU_COMMON -kernel "$image" | tee out/baremetal-$target.log
  grep -q "digests equal to the host's" out/baremetal-$target.log
  # .text: code; static RAM: .data + .bss (+ .heap where it has its own section), less the heap
  # array (sized for the check's dense LUT digest, test scaffolding like the golden frame, which
  # is read-only data and not counted).
  sections=$($CROSS bash -c "/usr/lib/llvm-22/bin/llvm-size -A $image")
  heap=$($CROSS bash -c "/usr/lib/llvm-22/bin/llvm-nm -S -t d $image" | awk '/HEAP_MEMORY/ { print $2 + 0 }')
  text=$(awk '$1 == ".text" { print $2 }' <<<"$sections")
  ram=$(awk '$1 == ".data" || $1 == ".bss" || $1 == ".heap" { s += $2 } END { print s + 0 }' <<<"$sections")
  echo "$target: .text $text bytes; static RAM (.data + .bss) $((ram - heap)) bytes, plus a heap of $heap bytes" | tee -a out/baremetal.log
done
echo "--- the host's digests (x86_64, the same check as a plain program):"
target/debug/satmap-baremetal
