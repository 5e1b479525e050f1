#!/usr/bin/env bash
# Coverage-guided fuzzing of the runtime's parsers with cargo fuzz (libFuzzer).
#
# Usage: fuzz/run.sh SECONDS [TARGET...]
#   Each target (all eight by default) runs SECONDS on a scratch corpus (target/fuzz-corpus/,
#   kept between runs, so a campaign resumes where the last one stopped) seeded from the
#   committed fuzz/seeds/<target>/, and prints one line: executions, edges covered (libFuzzer's
#   `cov`), corpus size and crashes. Any crash, timeout (> 10 s for one input) or out-of-memory
#   (> 2 GiB) fails the run and leaves the input in fuzz/artifacts/<target>/.
#
# cargo-fuzz comes from crates.io (`cargo install --locked`, once); stable Rust with
# `--sanitizer none` (the targets are safe Rust over the runtime's parsers: a panic is the
# finding; AddressSanitizer needs a nightly compiler, which this machine's registries do not
# offer). `make fuzz` runs the campaign, `make fuzz-ci` CI's slice.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:?usage: fuzz/run.sh SECONDS [TARGET...]}
shift
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(compiled_bundle signed_bundle nnef_stage nnef_text map_frame route_pack manifest
    mcap_recording)
fi
CARGO_FUZZ_VERSION=0.13.2
if ! cargo fuzz --version 2>/dev/null | grep -q "$CARGO_FUZZ_VERSION"; then
  cargo install --locked --quiet cargo-fuzz --version "$CARGO_FUZZ_VERSION"
fi
fuzz=(cargo fuzz run --sanitizer none --fuzz-dir fuzz)
cargo fuzz build --sanitizer none --fuzz-dir fuzz
mkdir -p out
status=0
for t in "${targets[@]}"; do
  corpus=target/fuzz-corpus/$t
  mkdir -p "$corpus" "fuzz/artifacts/$t"
  log=out/fuzz-$t.log
  if "${fuzz[@]}" "$t" "$corpus" "fuzz/seeds/$t" -- -max_total_time="$seconds" \
      -max_len=131072 -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
      -artifact_prefix="fuzz/artifacts/$t/" >"$log" 2>&1; then
    crashes=0
  else
    crashes=1
    status=1
  fi
  execs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "$log" | grep -o '[0-9]*$' || echo 0)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*$' || echo 0)
  corp=$(grep -o 'corp: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*$' || echo 0)
  echo "fuzz $t: ${seconds} s, execs $execs, edges covered $cov, corpus $corp, crashes $crashes"
  if [ "$crashes" -ne 0 ]; then
    echo "--- $log (tail):"
    tail -30 "$log"
  fi
done
exit $status
