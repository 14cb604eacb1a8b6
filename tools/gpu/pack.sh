#!/usr/bin/env bash
# Prepares what travels to a GPU machine lent through the `device` tool, into the ignored
# folder .gpu/ (name it in the run's `carry`): the release binary and every test binary
# (stripped, one xz archive), the Vulkan loader and validation-layer .debs, the gsplat
# wheel and FlashSplat's rasterizer sources for the side-by-side benchmarks. On the GPU
# machine, tools/gpu/device_run.sh unpacks and runs them. See docs/gpu.md.
#
# usage: bash tools/gpu/pack.sh            (needs tools/setup.sh's toolchain, apt, pip)
# env:   FLASHSPLAT_SRC  a git checkout or mirror of github.com/florinshen/flashsplat-rasterization
#                        (default: cloned from GitHub into a temporary folder)
#        GSPLAT_VERSION  default 1.5.3
#        BEFORE_BIN      another build's semsplat binary, for device_run.sh's BEFORE (a change
#                        timed against the build before it in the same run)
#        BUILDS          "NAME=PATH ..." further semsplat binaries for tools/gpu/builds_run.sh
#                        (several builds timed in interleaved rounds; NAME: letters, digits, _)
#        LIFT_SCENE      a `synth` folder (scene.ply, cameras.json, labels, labels_noisy) for
#                        device_run.sh's `lift` stage: fused there and here by
#                        tools/gpu/lift_run.sh, compared by tools/gpu/lift_check.py compare
set -euo pipefail
say() { printf '[pack] %s\n' "$*"; }
die() { printf '[pack] ERROR: %s\n' "$*" >&2; exit 1; }

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
cd "$repo"
out=.gpu
limit_mib=60 # the device tool carries 64 MiB in all, the repository's own files included
grep -qx '/.gpu/' .git/info/exclude 2>/dev/null || { mkdir -p .git/info; echo '/.gpu/' >>.git/info/exclude; }
rm -rf "$out" && mkdir -p "$out/stage/tests" "$out/debs" "$out/whl" "$out/src"

say "building the release binary and the test binaries"
cargo build --release --quiet
cargo test --release --no-run --message-format=json 2>/dev/null >"$out/artifacts.json"
python3 - "$out" <<'PY'
import json, shutil, sys
out = sys.argv[1]
names = []
for line in open(f"{out}/artifacts.json"):
    a = json.loads(line)
    if a.get("reason") != "compiler-artifact" or not a.get("executable") or not a["profile"]["test"]:
        continue
    t = a["target"]
    # Integration tests keep their name; the crate's own unit tests get the target kind.
    name = t["name"] if t["kind"] == ["test"] else f"{t['name']}-{t['kind'][0]}"
    shutil.copy(a["executable"], f"{out}/stage/tests/{name}")
    names.append(name)
print(f"[pack] {len(names)} test binaries")
PY
cp target/release/semsplat "$out/stage/semsplat"
# The consensus's host passes again on one run's observations (device_run.sh's host scaling).
cargo build --release --quiet --example consensus_host
cp target/release/examples/consensus_host "$out/stage/consensus_host"
strip "$out"/stage/semsplat "$out"/stage/consensus_host "$out"/stage/tests/*
pwd >"$out/built_at" # the test binaries look for the CLI and fixtures under this path
say "compressing $(du -sh "$out/stage" | cut -f1) of binaries"
tar -C "$out/stage" -cf - . | xz -9e -T0 >"$out/bins.tar.xz"
rm -rf "$out/stage" "$out/artifacts.json"

# The NVIDIA Vulkan driver (libGLX_nvidia) needs glvnd's dispatch libraries beside the loader.
say "downloading the Vulkan loader, glvnd and the validation layer (.deb)"
(cd "$out/debs" && apt-get download libvulkan1 libglvnd0 libglx0 libgl1 libegl1 libopengl0 \
  libgles2 vulkan-validationlayers >/dev/null 2>&1) \
  || die "apt-get download failed (run tools/setup.sh first; needs the Debian archive)"

say "downloading gsplat ${GSPLAT_VERSION:=1.5.3} (pure-Python wheel; its CUDA code is compiled on the GPU machine)"
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
  --implementation cp --platform manylinux2014_x86_64 -d "$out/whl" "gsplat==$GSPLAT_VERSION" \
  || die "pip download gsplat failed"

src=${FLASHSPLAT_SRC:-}
if [ -z "$src" ]; then
  src=$(mktemp -d)/flashsplat-rasterization
  git clone -q https://github.com/florinshen/flashsplat-rasterization "$src" \
    || die "cannot clone FlashSplat's rasterizer; set FLASHSPLAT_SRC to a checkout"
fi
commit=$(git -C "$src" rev-parse HEAD)
say "FlashSplat rasterizer at $commit"
# glm's documentation and tests are most of the repository and not needed to build.
git -C "$src" archive --prefix=flashsplat-rasterization/ HEAD \
  | tar --delete --wildcards 'flashsplat-rasterization/third_party/glm/doc' \
      'flashsplat-rasterization/third_party/glm/test' 2>/dev/null \
  | gzip -9 >"$out/src/flashsplat-rasterization.tar.gz"
echo "$commit" >"$out/src/flashsplat-rasterization.commit"

if [ -n "${BEFORE_BIN:-}" ]; then
  say "packing the build before: $BEFORE_BIN"
  strip -o "$out/before" "$BEFORE_BIN" && xz -9 -T0 "$out/before" || die "cannot pack $BEFORE_BIN"
fi

for build in ${BUILDS:-}; do
  name=${build%%=*} path=${build#*=}
  [[ $name =~ ^[A-Za-z0-9_]+$ && $name != "$build" ]] || die "BUILDS entries are NAME=PATH, got $build"
  say "packing build $name: $path"
  mkdir -p "$out/builds"
  strip -o "$out/builds/$name" "$path" && xz -9 -T0 "$out/builds/$name" || die "cannot pack $path"
done

if [ -n "${LIFT_SCENE:-}" ]; then
  say "packing the lift scene $LIFT_SCENE"
  mkdir -p "$out/lift"
  tar -C "$LIFT_SCENE" -cf - scene.ply cameras.json labels labels_noisy \
    $(cd "$LIFT_SCENE" && ls classes.json scene.classes.json 2>/dev/null) \
    | xz -6 -T0 >"$out/lift/scene.tar.xz" || die "cannot pack $LIFT_SCENE"
fi

size=$(du -sm "$out" | cut -f1)
tracked=$(git ls-files -z | du -cm --files0-from=- | tail -1 | cut -f1)
say "packed: $size MiB in $out (plus about $tracked MiB of tracked files)"
[ $((size + tracked)) -le $limit_mib ] || die "over the carry budget ($limit_mib MiB)"
