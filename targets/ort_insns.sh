#!/usr/bin/env bash
# onnxruntime's aarch64 wheel on the same stages as targets/insn_counts.sh, counted the same way
# (qemu-aarch64 with libinsn, the CPU of targets/cross.env, runs of 1 and 1 + N, difference / N).
# The ONNX stages of the committed `test` folder bundle, f32, one thread (targets/ort_stage.py).
#
# The aarch64 Python comes from Debian's arm64 packages (python3.13 and its libraries, unpacked
# into $SATMAP_CROSS_ROOT/opt/py-arm64/root: a sysroot for qemu's -L, nothing installed in the
# chroot), the wheels from PyPI at the versions models/pyproject.toml pins. Prints TSV rows
# (engine, precision, stage, instructions per run, CPU). Called by insn_counts.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${SATMAP_CROSS_ROOT:-/var/cache/satmap-cross/trixie}
CROSS=targets/in-chroot.sh
N=${1:-2}
STAGES=(image_encoder bev_query bev_encoder satellite_encoder map_decoder)
pin() { grep -oE "\"$1==[^\"]+\"" models/pyproject.toml | tr -d '"'; }
WHEELS=("$(pin onnxruntime)" "$(pin numpy)" "$(pin safetensors)")
STAMP=$ROOT/opt/py-arm64/.satmap-stamp
WANT=$(printf '%s\n' v1 "${WHEELS[@]}" | sha256sum | cut -c1-16)

if [[ ! -f "$STAMP" || "$(cat "$STAMP")" != "$WANT" ]]; then
  echo "--- aarch64 Python: Debian's arm64 python3.13, unpacked as a sysroot" >&2
  $CROSS --no-repo bash -euo pipefail -c '
    P=/opt/py-arm64
    rm -rf $P/root $P/site
    mkdir -p $P/state/lists/partial $P/cache/archives/partial
    : > $P/state/status
    # apt for arm64 alone, with an empty package database: the whole dependency closure is fetched.
    O="-o APT::Architecture=arm64 -o APT::Architectures::=arm64 -o Dir::State=$P/state -o Dir::State::status=$P/state/status -o Dir::Cache=$P/cache -o Debug::NoLocking=1"
    apt-get $O update -qq
    apt-get $O install -y -qq --download-only --no-install-recommends python3.13 libstdc++6 libgcc-s1 >/dev/null
    for d in $P/cache/archives/*.deb; do dpkg -x "$d" $P/root; done
    ln -s usr/lib $P/root/lib
  ' >&2
  echo "--- aarch64 Python: wheels ${WHEELS[*]}" >&2
  python3 -m pip install -q --target "$ROOT/opt/py-arm64/site" --python-version 3.13 \
    --implementation cp --abi cp313 --only-binary=:all: \
    --platform manylinux_2_28_aarch64 --platform manylinux_2_17_aarch64 --platform manylinux2014_aarch64 \
    "${WHEELS[@]}" >&2
  echo "$WANT" > "$STAMP"
fi

count() { # stage repeats -> total instructions of the process
  $CROSS bash -c 'R=/opt/py-arm64/root; PYTHONPATH=/opt/py-arm64/site PYTHONHASHSEED=0 \
    /opt/qemu-plugins/bin/qemu-aarch64 -cpu "$SATMAP_QEMU_CPU" -L $R -plugin /opt/qemu-plugins/lib/libinsn.so \
    -d plugin -D /tmp/insns.log $R/usr/bin/python3.13 targets/ort_stage.py models/bundles/test "$@" >&2 && \
    sed -n "s/^total insns: //p" /tmp/insns.log' _ "$1" "$2"
}
cpu=$($CROSS bash -c 'echo "$SATMAP_QEMU_CPU"')
version=${WHEELS[0]#onnxruntime==}
for s in "${STAGES[@]}"; do
  one=$(count "$s" 1)
  more=$(count "$s" $((1 + N)))
  printf 'onnxruntime-%s\tf32\t%s\t%s\t%s\n' "$version" "$s" $(( (more - one) / N )) "$cpu"
done
