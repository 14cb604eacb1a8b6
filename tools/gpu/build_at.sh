#!/usr/bin/env bash
# Builds another commit's semsplat release binary, for tools/gpu/pack.sh's BEFORE_BIN or
# BUILDS (a change timed on a GPU against the build before it). The commit is checked out
# in a temporary git worktree and built into this repository's target/ (its dependencies,
# shaderc's C++ build among them, are reused: about a minute where the current tree is
# built), then the binary is copied to OUT and the worktree removed.
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
tree=$(mktemp -d)/semsplat-$commit
trap 'git -C "$repo" worktree remove --force "$tree" 2>/dev/null || true' EXIT
git -C "$repo" worktree add -q --detach "$tree" "$commit"
(cd "$tree" && CARGO_TARGET_DIR="$repo/target" cargo build --release --quiet --bin semsplat) \
  || die "the build of $commit failed"
cp "$repo/target/release/semsplat" "$out"
printf '[build_at] %s: %s\n' "$commit" "$out"
# target/release/semsplat is now $commit's: the next build of the current tree relinks it.
