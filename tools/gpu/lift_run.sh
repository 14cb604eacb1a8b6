#!/usr/bin/env bash
# Fuses a `synth` scene's noisy train labels by FlashSplat, segment consensus and --relabel
# and evaluates each on the held-out views: the `lift` check, run the same way on the GPU
# machine (tools/gpu/device_run.sh lift) and here on lavapipe, then compared Gaussian by
# Gaussian with tools/gpu/lift_check.py compare.
#
# usage: bash tools/gpu/lift_run.sh SCENE_DIR OUT_DIR   (semsplat on PATH or SEMSPLAT=path)
# writes: OUT_DIR/NAME.npy (class per Gaussian), NAME.eval.json, seconds.txt
set -uo pipefail
scene=$1 out=$2
semsplat=${SEMSPLAT:-semsplat}
mkdir -p "$out"
failed=0
one() {
  local tag=$1; shift
  local t0; t0=$(date +%s%N)
  if "$semsplat" fuse --scene "$scene/scene.ply" --cameras "$scene/cameras.json" \
    --labels "$scene/labels_noisy" --train-only "$@" --out "$out/$tag.ply" >"$out/$tag.log" 2>&1; then
    echo "$tag $(( ($(date +%s%N) - t0) / 1000000 )) ms" >>"$out/seconds.txt"
    "$semsplat" eval --scene "$out/$tag.ply" --cameras "$scene/cameras.json" \
      --labels "$scene/labels" --views test --json "$out/$tag.eval.json" >>"$out/$tag.log" 2>&1 \
      || { echo "lift: $tag: no held-out evaluation (see $out/$tag.log)" >&2; failed=1; }
    if python3 "$(dirname "$0")/lift_check.py" extract "$out/$tag.ply" "$out/$tag.npy"; then
      rm -f "$out/$tag.ply" "$out/$tag.classes.json"
    else
      echo "lift: $tag: cannot read the classes of $out/$tag.ply (is numpy installed?)" >&2
      failed=1
    fi
  else
    echo "lift: $tag failed (see $out/$tag.log)" >&2
    failed=1
  fi
}
one flashsplat --method flashsplat
one consensus --method segment-consensus
one relabel --method segment-consensus --relabel
exit $failed
