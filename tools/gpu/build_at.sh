#!/usr/bin/env bash
# Builds another commit's semsplat release binary, for tools/gpu/pack.sh's BEFORE_BIN or
# BUILDS (a change timed on a GPU against the build before it). The commit is checked out
# in a temporary git worktree and built into this repository's target/ (its dependencies,
# shaderc's C++ build among them, are reused: about a minute where the current tree is
# built), then the binary is copied to OUT, the worktree removed and target/release/semsplat
# put back as it was.
#
# usage: bash tools/gpu/build_at.sh COMMIT OUT
#   e.g. bash tools/gpu/build_at.sh af0654f /tmp/semsplat_af0654f
#        BEFORE_BIN=/tmp/semsplat_af0654f bash tools/gpu/pack.sh
set -euo pipefail
die() { printf '[build_at] ERROR: %s\n' "$*" >&2; exit 1; }
[ $# -eq 2 ] || die "usage: build_at.sh COMMIT OUT"
commit=$1 out=$2
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
git -C "$repo" rev-parse --verify -q "$commit^{commit}" >/dev/null || die "no commit $commit"
tmp=$(mktemp -d)
tree=$tmp/semsplat-$commit
# The worktree's build writes its binary to target/release/semsplat, where cargo would not
# put the current tree's back (its own build is still fresh): the tests would run the other
# commit's CLI. Kept aside here and put back on the way out.
bin=$repo/target/release/semsplat
[ -f "$bin" ] && cp -p "$bin" "$tmp/kept"
restore() {
  [ -f "$tmp/kept" ] && cp -p "$tmp/kept" "$bin"
  git -C "$repo" worktree remove --force "$tree" 2>/dev/null || true
  rm -rf "$tmp"
}
trap restore EXIT
git -C "$repo" worktree add -q --detach "$tree" "$commit"
(cd "$tree" && CARGO_TARGET_DIR="$repo/target" cargo build --release --quiet --bin semsplat) \
  || die "the build of $commit failed"
cp "$bin" "$out"
printf '[build_at] %s: %s\n' "$commit" "$out"
