#!/usr/bin/env bash
# Instructions retired per stage on the application core, counted under emulation: the committed
# `test` bundles (f32, f16, int8) run stage by stage by tests/ecu/examples/stage_insns.rs, built
# for aarch64-unknown-linux-gnu (profile `test`: opt-level 3 everywhere, as the ECU tests), under
# qemu-aarch64 with Debian's qemu rebuilt with TCG plugins (targets/qemu_plugins.sh) and its
# `libinsn` plugin, on the CPU of targets/cross.env (Cortex-A76: NEON, FP16, dot product).
#
# Each stage runs in two processes, once and 1 + N times: the difference over N is one stage run,
# with loading, planning and first-run set-up cancelled out. The count is exact and the same on
# every run (one thread; the engine's pool is not started).
#
# Output: out/insn-counts.tsv (engine, precision, stage, instructions per run) and a Markdown table
# on stdout. With SATMAP_ORT_COUNTS=1 it also counts onnxruntime's aarch64 wheel on the same
# stages (targets/ort_insns.sh). A person's command (`make insn-counts`), about half an hour on 2 cores, not CI.
set -euo pipefail
cd "$(dirname "$0")/.."
CROSS=targets/in-chroot.sh
TARGET=aarch64-unknown-linux-gnu
N=${SATMAP_INSN_REPEATS:-8}
STAGES=(image_encoder bev_query bev_encoder satellite_encoder map_decoder)
PRECISIONS=(${SATMAP_INSN_PRECISIONS:-f32 f16-widened f16 int8})

bash targets/toolchain.sh
bash targets/qemu_plugins.sh
echo "--- insn counts: build stage_insns for $TARGET"
$CROSS cargo build --profile test --target $TARGET -p satmap-ecu-tests --example stage_insns
BIN=target/cross/$TARGET/debug/examples/stage_insns

mkdir -p out
TSV=out/insn-counts.tsv
: > "$TSV.part"
count() { # precision stage repeats -> total instructions of the process
  $CROSS bash -c '/opt/qemu-plugins/bin/qemu-aarch64 -cpu "$SATMAP_QEMU_CPU" -L /usr/aarch64-linux-gnu \
    -plugin /opt/qemu-plugins/lib/libinsn.so -d plugin -D /tmp/insns.log "$@" >&2 && \
    sed -n "s/^total insns: //p" /tmp/insns.log' _ "$BIN" "$1" "$2" "$3"
}
cpu=$($CROSS bash -c 'echo "$SATMAP_QEMU_CPU"')
for p in "${PRECISIONS[@]}"; do
  for s in "${STAGES[@]}"; do
    one=$(count "$p" "$s" 1)
    more=$(count "$p" "$s" $((1 + N)))
    per=$(( (more - one) / N ))
    printf 'satmap-tract\t%s\t%s\t%s\t%s\n' "$p" "$s" "$per" "$cpu" | tee -a "$TSV.part"
  done
done
if [[ "${SATMAP_ORT_COUNTS:-0}" == 1 ]]; then
  bash targets/ort_insns.sh "$N" | tee -a "$TSV.part"
fi
mv "$TSV.part" "$TSV"

echo
echo "Instructions per stage run (millions), qemu-aarch64 -cpu $cpu, libinsn; weights: committed \`test\`"
awk -F'\t' '
  { key = $1 " " $2; if (!(key in seen)) { seen[key] = 1; cols[++nc] = key }
    if (!($3 in srow)) { srow[$3] = 1; rows[++nr] = $3 }
    v[$3, key] = $4 }
  END {
    printf "| stage |"; for (c = 1; c <= nc; c++) printf " %s |", cols[c]; print ""
    printf "|---|"; for (c = 1; c <= nc; c++) printf "---:|"; print ""
    for (r = 1; r <= nr; r++) {
      printf "| %s |", rows[r]
      for (c = 1; c <= nc; c++) {
        x = v[rows[r], cols[c]]; if (x == "") printf " - |"; else printf " %.1f |", x / 1e6
      }
      print ""
    }
  }' "$TSV"
