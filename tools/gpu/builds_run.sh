#!/usr/bin/env bash
# Runs on a GPU machine lent through the `device` tool, carrying .gpu/ from tools/gpu/pack.sh
# with BUILDS set: the forward and fusion cases most sensitive to the per-tile kernels' code,
# with this build and every packed build, in interleaved rounds (round 1: each build once,
# then round 2 ...), so a drift of the machine over the run touches every build alike.
# Where device_run.sh's BEFORE times two builds, this times several (e.g. forms of a kernel).
# Writes $OUT/builds.jsonl (each `bench --json` line with "case", "build", "round"),
# builds.log, and device_run.sh's summary.txt and info.txt (its STAGES run first: e.g.
# "tests" with TESTS=regex to run test binaries of this build too).
#
# usage: bash tools/gpu/builds_run.sh
# env:   ROUNDS (default 2); CASES: a regular expression on the case names below;
#        STAGES (default none): device_run.sh's stages to run first; N, W, H, VIEWS: sizes
#        (1000000, 1920x1080, 200 views), SPACING and ROOM_FUSE_SPACING the rooms' (0.0053,
#        0.0115, as device_run.sh's): smaller and coarser for a dry run on lavapipe.
set -uo pipefail
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
gpu=.gpu
# device_run.sh unpacks this build into /opt/semsplat and the Vulkan loader into /, and
# checks that the device is there; with no stage named it runs nothing else.
bash tools/gpu/device_run.sh ${STAGES:-none} || exit $?
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f "$icd" ] && export VK_DRIVER_FILES=$icd VK_ICD_FILENAMES=$icd
declare -A exe=([this]=/opt/semsplat/semsplat)
names=(this)
for f in "$gpu"/builds/*.xz; do
  [ -e "$f" ] || continue
  name=$(basename "$f" .xz)
  xz -dc "$f" >"/tmp/build_$name" && chmod +x "/tmp/build_$name" && exe[$name]=/tmp/build_$name &&
    names+=("$name")
done
log=$OUT/builds.log
semsplat=${exe[this]}
# The rooms only where a case CASES selects reads them (each takes seconds to minutes).
wanted() { [[ $1 =~ ${CASES:-.} ]]; }
if wanted "render room C=0" || wanted "render room C=16" || wanted "render room C=64"; then
  $semsplat synth --preset office --spacing "${SPACING:-0.0053}" --views 1 --test-views 0 \
    --width "${W:-1920}" --height "${H:-1080}" --out /tmp/room >>"$log" 2>&1 ||
    echo "synth room failed" >>"$OUT/summary.txt"
fi
if wanted "fuse room x ${VIEWS:-200}"; then
  $semsplat synth --preset office --spacing "${ROOM_FUSE_SPACING:-0.0115}" --views "${VIEWS:-200}" \
    --test-views 0 --width 96 --height 54 --no-previews --out /tmp/room_fuse >>"$log" 2>&1 ||
    echo "synth room_fuse failed" >>"$OUT/summary.txt"
fi

# One case with one build: its JSON line, marked, appended to builds.jsonl.
one() {
  local build=$1 round=$2 case=$3; shift 3
  wanted "$case" || return 0
  echo "=== $case ($build, round $round): semsplat $*" >>"$log"
  if "${exe[$build]}" "$@" --json >/tmp/case.json 2>>"$log"; then
    python3 -c 'import json,sys; d=json.load(open("/tmp/case.json"))
d.update(case=sys.argv[1], build=sys.argv[2], round=int(sys.argv[3])); print(json.dumps(d))' \
      "$case" "$build" "$round" >>"$OUT/builds.jsonl"
  else
    echo "FAILED $case ($build)" >>"$OUT/summary.txt"
  fi
}

start=$(date +%s)
for round in $(seq "${ROUNDS:-2}"); do
  for build in "${names[@]}"; do
    for c in 0 16 64; do
      one "$build" "$round" "render room C=$c" bench render --scene /tmp/room --channels $c --iters 20
    done
    one "$build" "$round" "render random C=16" bench render --n "${N:-1000000}" \
      --width "${W:-1920}" --height "${H:-1080}" --channels 16 --iters 10
    one "$build" "$round" "fuse room x ${VIEWS:-200}" bench fuse --scene /tmp/room_fuse \
      --views "${VIEWS:-200}" --width "${W:-1920}" --height "${H:-1080}" --classes 16 \
      --methods flashsplat
    echo "[$(($(date +%s) - start))s] round $round: $build" | tee -a "$OUT/summary.txt"
  done
done
