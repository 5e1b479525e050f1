#!/usr/bin/env bash
# Runs a command inside the cross-toolchain chroot (targets/toolchain.sh), in a private mount
# namespace: /proc, /sys, /dev and the repository are mounted for this command only and vanish
# with it, so nothing stays mounted under the cache (an `rm -rf` of the cache can never reach the
# host's /dev or the work tree). The repository appears at the same path as on the host, so
# paths in cargo's output, in tests and in Make variables mean the same thing inside and out.
#
#   targets/in-chroot.sh CMD ARGS...       run CMD in the repository's folder
#   targets/in-chroot.sh --no-repo CMD...  run CMD without mounting the repository (set-up)
#
# The host's crate registry cache is shared (the same crates are not downloaded twice). The cross
# settings for aarch64-unknown-linux-gnu (linker, C compiler, qemu runner with the emulated CPU
# chosen in targets/cross.env) are exported.
set -euo pipefail

ROOT=${SATMAP_CROSS_ROOT:-/var/cache/satmap-cross/trixie}
HERE=$(cd "$(dirname "$0")" && pwd)
REPO=$(cd "$HERE/.." && pwd)
MOUNT_REPO=1
if [[ "${1:-}" == "--no-repo" ]]; then
  MOUNT_REPO=0
  shift
fi
[[ $# -gt 0 ]] || { echo "usage: $0 [--no-repo] CMD ARGS..." >&2; exit 2; }
[[ -x "$ROOT/usr/bin/apt-get" ]] || { echo "no cross toolchain in $ROOT: run targets/toolchain.sh" >&2; exit 2; }

HOST_REGISTRY=${CARGO_HOME:-$HOME/.cargo}/registry
mkdir -p "$HOST_REGISTRY"
WORKDIR=$PWD
[[ "$WORKDIR" == "$REPO"* ]] || WORKDIR=$REPO

# The environment inside: nothing of the host's but what the build needs.
ENV=(HOME=/root PATH=/usr/lib/rust-web/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 TERM=dumb)
for v in CI CARGO_INCREMENTAL CARGO_TERM_COLOR RUST_BACKTRACE RUST_TEST_THREADS QEMU_CPU \
  http_proxy https_proxy HTTP_PROXY HTTPS_PROXY no_proxy NO_PROXY; do
  [[ -n "${!v:-}" ]] && ENV+=("$v=${!v}")
done
# Every SATMAP_* variable passes (test knobs, bundle paths), except the chroot's own root.
while IFS='=' read -r k _; do
  [[ "$k" == SATMAP_* && "$k" != SATMAP_CROSS_ROOT ]] && ENV+=("$k=${!k}")
done < <(env)
# shellcheck source=targets/cross.env
source "$HERE/cross.env"
ENV+=("${CROSS_ENV[@]}")

exec unshare --mount --propagation private bash -euo pipefail -c '
  root=$1 repo=$2 mount_repo=$3 registry=$4 workdir=$5 n_env=$6; shift 6
  env_vars=("${@:1:n_env}"); shift "$n_env"
  mount -t proc proc "$root/proc"
  mount --rbind /sys "$root/sys"
  mount --rbind /dev "$root/dev"
  mkdir -p "$root/root/.cargo/registry"
  mount --bind "$registry" "$root/root/.cargo/registry"
  cd_to=/
  if [[ $mount_repo == 1 ]]; then
    mkdir -p "$root$repo"
    mount --bind "$repo" "$root$repo"
    cd_to=$workdir
  fi
  exec chroot "$root" /usr/bin/env -i "${env_vars[@]}" bash -c "cd \"\$0\" && exec \"\$@\"" "$cd_to" "$@"
' _ "$ROOT" "$REPO" "$MOUNT_REPO" "$HOST_REGISTRY" "$WORKDIR" "${#ENV[@]}" "${ENV[@]}" "$@"
