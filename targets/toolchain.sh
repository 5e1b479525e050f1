#!/usr/bin/env bash
# Installs the cross toolchain for the ECU targets, from Debian's packages only, into a Debian
# trixie chroot cached outside the repository (SATMAP_CROSS_ROOT, default
# /var/cache/satmap-cross/trixie). Idempotent: a second run with the same package list returns at
# once. Why a chroot: the machine's rustup toolchain carries the x86_64 standard library only and
# no std sources, and no other toolchain can be downloaded; Debian trixie packages a current Rust
# with aarch64's std (multiarch) and the std sources for `-Z build-std` (bare-metal targets), and
# trixie's rustc needs trixie's glibc and LLVM. See ../shared/reference/CROSS_TARGETS.md for the
# trial this follows and targets/README.md for what runs where.
#
# Needs root (debootstrap, chroot, mounts). ~1 min for the base system, ~3 min for the packages
# (about 3 GB on disk), network-bound.
set -euo pipefail

ROOT=${SATMAP_CROSS_ROOT:-/var/cache/satmap-cross/trixie}
HERE=$(cd "$(dirname "$0")" && pwd)

# The chroot's packages. Changing this list changes the stamp, so the next run installs again.
PACKAGES=(
  # Rust 1.96 by Debian, the aarch64 std (multiarch) and the std sources for -Z build-std.
  rustc-web cargo-web libstd-rust-web-dev libstd-rust-web-dev:arm64 rust-web-src
  # rust-lld (a link to lld-22): the linker the *-none targets default to.
  rust-web-llvm lld-22
  # Host C toolchain (build scripts link with it) and the aarch64 cross toolchain (tract-linalg's
  # NEON assembly, the final link, the C example).
  gcc libc6-dev gcc-aarch64-linux-gnu libc6-dev-arm64-cross
  # User-mode emulation (aarch64 Linux binaries) and system emulation (bare-metal images:
  # qemu-system-aarch64 and qemu-system-arm both come with qemu-system-arm).
  qemu-user qemu-system-arm
  make ca-certificates git
)
STAMP="$ROOT/.satmap-toolchain"
WANT=$(printf '%s\n' "v1" "${PACKAGES[@]}" | sha256sum | cut -c1-16)

# The downloaded .deb files stay in apt's cache after an install (~500 MB): disk CI may not have.
drop_debs() {
  find "$ROOT/var/cache/apt/archives" -maxdepth 1 -name '*.deb' -delete 2>/dev/null || true
}

if [[ -f "$STAMP" && "$(cat "$STAMP")" == "$WANT" ]]; then
  drop_debs
  echo "cross toolchain: ready in $ROOT"
  exit 0
fi

if ! command -v debootstrap >/dev/null; then
  # `make test` installs valgrind on the host at the same time: both take this lock.
  flock /tmp/satmap-apt.lock sh -c 'apt-get update -qq && apt-get install -y -qq debootstrap >/dev/null'
fi

# The Debian mirror the host already uses (the only one reachable here).
MIRROR=$(grep -rhE '^[[:space:]]*(URIs:|deb )' /etc/apt/sources.list /etc/apt/sources.list.d/ 2>/dev/null \
  | grep -oE 'https?://[^ ]*debian[^ ]*' | grep -v security | head -n1 || true)
MIRROR=${MIRROR:-http://deb.debian.org/debian}

if [[ ! -x "$ROOT/usr/bin/apt-get" ]]; then
  echo "cross toolchain: debootstrap trixie into $ROOT (mirror $MIRROR)"
  rm -rf --one-file-system "$ROOT"
  mkdir -p "$ROOT"
  debootstrap --variant=minbase --include=ca-certificates trixie "$ROOT" "$MIRROR" >/dev/null
fi

# Name resolution and the host's extra certificate authorities (without them cargo inside the
# chroot cannot reach the crate registry through this network's proxy).
cp -L /etc/resolv.conf "$ROOT/etc/resolv.conf"
mkdir -p "$ROOT/usr/local/share/ca-certificates"
cp /usr/local/share/ca-certificates/*.crt "$ROOT/usr/local/share/ca-certificates/" 2>/dev/null || true
for v in http_proxy https_proxy HTTP_PROXY HTTPS_PROXY no_proxy NO_PROXY; do
  [[ -n "${!v:-}" ]] && echo "export $v=${!v}"
done > "$ROOT/etc/profile.d/satmap-proxy.sh"

echo "cross toolchain: installing ${#PACKAGES[@]} packages"
"$HERE/in-chroot.sh" --no-repo bash -euo pipefail -c "
  update-ca-certificates >/dev/null
  dpkg --add-architecture arm64
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends ${PACKAGES[*]} >/dev/null
  rustc --version; cargo --version; aarch64-linux-gnu-gcc --version | head -n1
  qemu-aarch64 --version | head -n1; qemu-system-aarch64 --version | head -n1
"
drop_debs
echo "$WANT" > "$STAMP"
echo "cross toolchain: ready in $ROOT"
