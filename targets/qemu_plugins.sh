#!/usr/bin/env bash
# Builds qemu-aarch64 (user mode) with TCG plugins from Debian trixie's own qemu source package,
# inside the cross-toolchain chroot, and its instruction-counting plugin (libinsn.so). Debian
# builds qemu without plugin support (`-plugin` is not an option of its qemu-aarch64), and no
# other qemu can be fetched here: the source is the one Debian ships, patched as Debian ships it.
#
# Output (outside the repository, idempotent by stamp): $SATMAP_CROSS_ROOT/opt/qemu-plugins/
#   bin/qemu-aarch64, lib/libinsn.so  (inside the chroot: /opt/qemu-plugins/...)
#
# A person's command (`make insn-counts` calls it), never a CI step: a few minutes on 2 cores (one user-mode target), once.
set -euo pipefail

ROOT=${SATMAP_CROSS_ROOT:-/var/cache/satmap-cross/trixie}
HERE=$(cd "$(dirname "$0")" && pwd)
STAMP="$ROOT/opt/qemu-plugins/.satmap-stamp"
WANT=v1-aarch64-linux-user-plugins

[[ -x "$ROOT/usr/bin/apt-get" ]] || { echo "no cross toolchain in $ROOT: run make cross-toolchain" >&2; exit 2; }
if [[ -f "$STAMP" && "$(cat "$STAMP")" == "$WANT" ]]; then
  echo "qemu with plugins: ready in $ROOT/opt/qemu-plugins"
  exit 0
fi

"$HERE/in-chroot.sh" --no-repo bash -euo pipefail -c '
  src_list=/etc/apt/sources.list.d/satmap-src.list
  [[ -f $src_list ]] || sed -n "s/^deb /deb-src /p" /etc/apt/sources.list.d/*.list /etc/apt/sources.list 2>/dev/null | sort -u > $src_list
  apt-get update -qq
  # What configure needs for a user-mode target (no system emulation, no docs).
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    dpkg-dev xz-utils python3 python3-venv meson ninja-build pkg-config libglib2.0-dev flex bison >/dev/null
  mkdir -p /opt/qemu-src && cd /opt/qemu-src
  [[ -n $(ls -d qemu-*/ 2>/dev/null) ]] || apt-get source -qq qemu >/dev/null
  cd "$(ls -d qemu-*/ | head -n1)"
  mkdir -p build-plugins && cd build-plugins
  [[ -f build.ninja ]] || ../configure --prefix=/opt/qemu-plugins --target-list=aarch64-linux-user \
    --enable-plugins --disable-docs --disable-tools --disable-system --disable-install-blobs --disable-werror >/dev/null
  ninja -j"$(nproc)" qemu-aarch64 >/dev/null
  # The plugins qemu ships as examples: libinsn counts instructions executed.
  ninja -j"$(nproc)" $(ninja -t targets all | grep -oE "^tests/tcg/plugins/libinsn\.so" | head -n1) >/dev/null
  mkdir -p /opt/qemu-plugins/bin /opt/qemu-plugins/lib
  cp qemu-aarch64 /opt/qemu-plugins/bin/
  cp tests/tcg/plugins/libinsn.so /opt/qemu-plugins/lib/
  /opt/qemu-plugins/bin/qemu-aarch64 --version | head -n1
'
echo "$WANT" > "$STAMP"
echo "qemu with plugins: ready in $ROOT/opt/qemu-plugins"
