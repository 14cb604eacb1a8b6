#!/usr/bin/env python3
"""The `lift` stage's check: the same fusion on the GPU and on lavapipe, Gaussian by Gaussian.

  lift_check.py extract FUSED.ply OUT.npy   per-Gaussian `class` of a fused PLY (int32)
  lift_check.py compare GPU_DIR HERE_DIR    for every NAME.npy in both: how many Gaussians
                                            got another class, and the held-out mIoU of each
                                            (NAME.eval.json, written by `semsplat eval --json`)

The GPU sums evidence with float or fixed-point atomics in another order than lavapipe, so a
Gaussian whose top two classes tie within rounding may differ; anything more is a bug.
"""
import json
import sys

import numpy as np

TYPES = {"float": "<f4", "int": "<i4", "uint": "<u4", "uchar": "u1", "double": "<f8"}


def read_ply(path):
    with open(path, "rb") as f:
        props, n = [], 0
        while True:
            line = f.readline().decode().strip()
            if line.startswith("element vertex"):
                n = int(line.split()[2])
            elif line.startswith("property"):
                _, kind, name = line.split()
                props.append((name, TYPES[kind]))
            elif line == "end_header":
                break
        return np.frombuffer(f.read(), dtype=np.dtype(props), count=n)


def miou(path):
    try:
        return json.load(open(path)).get("miou")
    except (OSError, ValueError):
        return None


def compare(gpu_dir, here_dir):
    import os

    worst = 0.0
    for name in sorted(os.listdir(gpu_dir)):
        if not name.endswith(".npy") or not os.path.exists(f"{here_dir}/{name}"):
            continue
        a, b = np.load(f"{gpu_dir}/{name}"), np.load(f"{here_dir}/{name}")
        if a.shape != b.shape:
            print(f"{name}: {a.shape} Gaussians on the GPU, {b.shape} here")
            worst = 1.0
            continue
        diff = int((a != b).sum())
        worst = max(worst, diff / len(a))
        stem = name[: -len(".npy")]
        print(
            f"{stem}: {diff} of {len(a)} Gaussians differ ({100 * diff / len(a):.3f}%); "
            f"held-out mIoU GPU {miou(f'{gpu_dir}/{stem}.eval.json')} "
            f"here {miou(f'{here_dir}/{stem}.eval.json')}"
        )
    return worst


if __name__ == "__main__":
    if sys.argv[1:2] == ["extract"]:
        np.save(sys.argv[3], read_ply(sys.argv[2])["class"].astype(np.int32))
    elif sys.argv[1:2] == ["compare"]:
        compare(sys.argv[2], sys.argv[3])
    else:
        sys.exit(__doc__)
