#!/usr/bin/env bash
# The lifting methods on a *trained* scene: a synth room's Gaussians are exact surface
# samples (thin, opaque shells), a trained 3DGS is not (Gaussians spread about surfaces,
# large ones across edges, floaters, faint shells). This builds a room with `synth`, trains
# its geometry from the room's init point cloud on the train views' images (no semantic
# loss: the labels do not shape the geometry), then fuses the clean and the noisy train
# labels onto the trained Gaussians with each method and scores the held-out views against
# the true labels. See docs/robustness-log.md, "On a trained scene".
#
# usage: bash tools/trained_check.sh OUT_DIR
# env:   PRESET (living), SEED (3), NOISE (flicker=0.3), VIEWS (60), TEST_VIEWS (8),
#        WIDTH (320), HEIGHT (240), ITERS (1000), MAX_GAUSSIANS (100000),
#        DETERMINISTIC (0; 1: `train --deterministic`, the same trained scene on every
#        run with the same device and driver, its backward slower; without it two
#        trainings differ and a trained scene's figures can move by a point),
#        METHODS ("flashsplat|segment-consensus|segment-consensus --relabel|vote --occlusion"),
#        SEMSPLAT (the binary; default target/release/semsplat, built if missing)
# Reruns reuse OUT_DIR's room and trained scene when asked for the same settings (and stop
# when asked for others; delete them to redo). Training takes about
# 25 minutes on lavapipe with two cores at the defaults; each fusion seconds.
# Writes OUT_DIR/summary.json and prints a table: held-out mIoU and pixel accuracy per
# method and labels, on the room's own Gaussians and on the trained ones, and each scene's
# held-out PSNR.
set -euo pipefail
say() { printf '[trained_check] %s\n' "$*"; }
die() { printf '[trained_check] ERROR: %s\n' "$*" >&2; exit 1; }

[ $# -eq 1 ] || die "usage: bash tools/trained_check.sh OUT_DIR"
command -v python3 >/dev/null || die "python3 is needed for the summary table"
deterministic=()
case ${DETERMINISTIC:-0} in
    0) ;;
    1) deterministic=(--deterministic) ;;
    *) die "DETERMINISTIC must be 0 or 1, not '$DETERMINISTIC'" ;;
esac
out=$(mkdir -p "$1" && cd "$1" && pwd)
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin=${SEMSPLAT:-$repo/target/release/semsplat}
if [ ! -x "$bin" ]; then
    say "building $bin"
    (cd "$repo" && cargo build --release --quiet)
fi
preset=${PRESET:-living} seed=${SEED:-3} noise=${NOISE:-flicker=0.3}
IFS='|' read -r -a methods <<<"${METHODS:-flashsplat|segment-consensus|segment-consensus --relabel|vote --occlusion}"

# What made the room and the trained scene: a rerun reuses them only if asked for the same
# (another SEED into the same OUT_DIR would otherwise be scored as if it were that seed).
room_settings="preset=$preset seed=$seed noise=$noise views=${VIEWS:-60} test_views=${TEST_VIEWS:-8} size=${WIDTH:-320}x${HEIGHT:-240}"
train_settings="$room_settings iters=${ITERS:-1000} max_gaussians=${MAX_GAUSSIANS:-100000} deterministic=${DETERMINISTIC:-0}"
# reuse_or_not FILE SETTINGS RECORD: true if RECORD exists and holds SETTINGS; stops if it
# holds others.
reuse_or_not() {
    [ -f "$1" ] && [ -f "$3" ] || return 1
    [ "$(cat "$3")" = "$2" ] && return 0
    die "$1 was made with '$(cat "$3")', not '$2': use another OUT_DIR, or delete it"
}

room=$out/room
if ! reuse_or_not "$room/scene.ply" "$room_settings" "$out/room.settings"; then
    say "synth $preset seed $seed, $noise"
    rm -f "$out/room.settings" "$out/trained.settings"
    "$bin" synth --preset "$preset" --seed "$seed" --noise "$noise" --views "${VIEWS:-60}" \
        --test-views "${TEST_VIEWS:-8}" --width "${WIDTH:-320}" --height "${HEIGHT:-240}" \
        --out "$room" --no-previews --force
    printf '%s\n' "$room_settings" >"$out/room.settings"
fi
trained=$out/trained.ply
if ! reuse_or_not "$trained" "$train_settings" "$out/trained.settings"; then
    say "training ${ITERS:-1000} iterations from init.ply (geometry and colour only)"
    "$bin" train --images "$room/images" --labels "$room/labels" --cameras "$room/cameras.json" \
        --init "$room/init.ply" --out "$trained" --iters "${ITERS:-1000}" --lambda-sem 0 \
        --train-only --max-gaussians "${MAX_GAUSSIANS:-100000}" --report "$out/train.json" \
        "${deterministic[@]}"
    printf '%s\n' "$train_settings" >"$out/trained.settings"
fi

# fuse_and_score SCENE_TAG SCENE_PLY LABELS METHOD...: one fusion, scored; its eval JSON path.
fuse_and_score() {
    local tag=$1 scene=$2 labels=$3
    shift 3
    local name
    name=$(printf '%s' "$*" | tr -c 'a-z0-9' '_')
    local fused=$out/fused/$tag.$labels.$name
    mkdir -p "$out/fused"
    "$bin" fuse --scene "$scene" --cameras "$room/cameras.json" --labels "$room/$labels" \
        --classes "$room/classes.json" --method "$@" --train-only --out "$fused.ply" \
        >"$fused.fuse.log" 2>&1 || die "fuse failed, see $fused.fuse.log"
    "$bin" eval --scene "$fused.ply" --cameras "$room/cameras.json" --labels "$room/labels" \
        --classes "$room/classes.json" --images "$room/images" --json "$fused.eval.json" \
        >"$fused.eval.log" 2>&1 || die "eval failed, see $fused.eval.log"
    printf '%s\t%s\t%s\t%s\n' "$tag" "$labels" "$*" "$fused.eval.json" >>"$out/runs.tsv"
}

rm -f "$out/runs.tsv"
for tag in room trained; do
    scene=$room/scene.ply
    [ "$tag" = trained ] && scene=$trained
    for labels in labels labels_noisy; do
        for m in "${methods[@]}"; do
            say "$tag, $labels: $m"
            # shellcheck disable=SC2086 # a method and its flags, split on purpose
            fuse_and_score "$tag" "$scene" "$labels" $m
        done
    done
done

python3 - "$out" "$train_settings" <<'EOF'
import json, sys
out, settings = sys.argv[1], sys.argv[2]
runs = []
for line in open(f"{out}/runs.tsv"):
    tag, labels, method, path = line.rstrip("\n").split("\t")
    e = json.load(open(path))
    runs.append({"scene": tag, "labels": labels, "method": method, "miou": e["miou"],
                 "pixel_accuracy": e["pixel_accuracy"],
                 "psnr": (e.get("image_quality") or {}).get("psnr"),
                 "per_class": e["per_class"]})
json.dump({"settings": settings, "runs": runs}, open(f"{out}/summary.json", "w"), indent=1)
print(f"{'scene':8} {'labels':13} {'method':30} {'mIoU':>7} {'pixel':>7} {'PSNR':>6}")
for r in runs:
    print(f"{r['scene']:8} {r['labels']:13} {r['method']:30} {r['miou']:7.4f} "
          f"{r['pixel_accuracy']:7.4f} {r['psnr'] or float('nan'):6.2f}")
EOF
