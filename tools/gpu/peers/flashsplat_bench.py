"""FlashSplat's rasterizer (florinshen/flashsplat-rasterization) lifting a semsplat fusion
export's label maps to the Gaussians, timed the way FlashSplat's render.py drives it.

  PYTHONPATH=/tmp/site:tools/gpu/peers python3 tools/gpu/peers/flashsplat_bench.py \
    --scene DIR --out flashsplat.json [--views K] [--commit HASH] [--save-classes c.npy]

Per view (render.py's render_set): upload that view's label map to the GPU as float
[H, W] (timed; from pinned host int16 prepared before the loop, unlabeled already mapped
to K), render with gt_mask (used_count [num_obj + 1, N] += alpha * T at row label[pixel]),
all_counts += used_count. One view is rendered first as a warm-up (not timed).

Rows: labels are 0..K-1 and unlabeled (65535) -> K. num_obj = K + 1, so every label is
< num_obj as render.py asserts; the rasterizer allocates num_obj + 1 = K + 2 rows (the last
never written, as in FlashSplat's own use).
Assignment: render.py's multi_instance_opt (L1-normalize over rows, then per row argmax of
[sum - row, row]; slackness 0) is timed as assign_s; a plain argmax over rows 0..K-1 as
assign_argmax_s.
"""

import argparse
import json
import math
import os
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scene_io  # noqa: E402


def log(*a):
    print(*a, flush=True)


def multi_instance_opt(all_counts, slackness=0.0):
    """FlashSplat render.py's multi_instance_opt, without the tqdm progress bar."""
    all_counts = torch.nn.functional.normalize(all_counts, dim=0, p=1)
    all_counts_sum = all_counts.sum(dim=0)
    all_obj_labels = torch.zeros_like(all_counts)
    for obj_idx, obj_counts in enumerate(all_counts):
        if obj_counts.sum().item() == 0:
            continue
        obj_counts = torch.stack([all_counts_sum - obj_counts, obj_counts], dim=0)
        if slackness != 0:
            obj_counts = torch.nn.functional.normalize(obj_counts, dim=0)
            obj_counts[0, :] += slackness
        obj_label = obj_counts.max(dim=0)[1]
        all_obj_labels[obj_idx] = obj_label
    return all_obj_labels


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", required=True, help="semsplat bench --export folder with labels.npy")
    ap.add_argument("--out", help="JSON file (a list of runs; this run appended)")
    ap.add_argument("--views", type=int, default=0, help="first K views (default: all)")
    ap.add_argument("--warmup", type=int, default=1, help="untimed warm-up views")
    ap.add_argument("--commit", default=None, help="flashsplat-rasterization commit, recorded")
    ap.add_argument("--label", default=None, help="scene label in the JSON")
    ap.add_argument("--save-classes", default=None,
                    help="write int32 [N]: argmax over rows 0..K-1, -1 without evidence")
    args = ap.parse_args()

    if not torch.cuda.is_available():
        sys.exit("CUDA is not available")
    from flashsplat_rasterization import GaussianRasterizationSettings, GaussianRasterizer
    dev = torch.device("cuda")

    bench = scene_io.read_bench(args.scene)
    g = scene_io.load_gaussians(os.path.join(args.scene, "scene.ply"))
    cams = scene_io.read_cameras(os.path.join(args.scene, "cameras.json"))
    labels = np.load(os.path.join(args.scene, "labels.npy"), mmap_mode="r")
    k_classes = int(bench["classes"])
    no_label = int(bench.get("no_label", scene_io.NO_LABEL))
    v_all, h, w = labels.shape
    if v_all != len(cams["names"]):
        sys.exit(f"labels.npy has {v_all} views, cameras.json {len(cams['names'])}")
    v = min(args.views, v_all) if args.views > 0 else v_all
    if k_classes + 1 >= 32767:
        sys.exit("too many classes for the int16 label staging")
    num_obj = k_classes + 1
    n = g["n"]
    log(f"scene: N={n} SH degree {g['sh_degree']} {w}x{h}, {v} of {v_all} views, "
        f"K={k_classes} classes, num_obj={num_obj} ({num_obj + 1} used_count rows)")

    # Gaussians, activated, as INRIA's GaussianModel getters return them.
    means = torch.from_numpy(g["means"]).to(dev).contiguous()
    opac = torch.from_numpy(g["opacities"]).to(dev)[:, None].contiguous()  # [N,1]
    scales = torch.from_numpy(g["scales"]).to(dev).contiguous()
    rots = torch.from_numpy(g["quats"]).to(dev).contiguous()  # w,x,y,z normalized
    shs = torch.from_numpy(g["sh"]).to(dev).contiguous()  # [N,K,3]
    means2d = torch.zeros_like(means)
    bg = torch.zeros(3, device=dev)

    # Per-view INRIA cameras.
    near = float(bench.get("near", 0.01))
    far = float(bench.get("far", 1e10))
    settings = []
    for i in range(v):
        if int(cams["widths"][i]) != w or int(cams["heights"][i]) != h:
            sys.exit(f"camera {i} is not {w}x{h}")
        ic = scene_io.inria_camera(cams["viewmats64"][i], cams["fx"][i], cams["fy"][i],
                                   cams["cx"][i], cams["cy"][i], w, h, znear=near, zfar=far)
        settings.append(GaussianRasterizationSettings(
            image_height=h, image_width=w,
            tanfovx=ic["tanfovx"], tanfovy=ic["tanfovy"],
            bg=bg, scale_modifier=1.0,
            viewmatrix=torch.from_numpy(ic["world_view_transform"]).to(dev).contiguous(),
            projmatrix=torch.from_numpy(ic["full_proj_transform"]).to(dev).contiguous(),
            sh_degree=g["sh_degree"],
            campos=torch.from_numpy(ic["campos"]).to(dev).contiguous(),
            prefiltered=False, debug=False, mask_grad=False, num_obj=num_obj))

    # Label maps staged in pinned host memory (int16, unlabeled -> K) before timing.
    t0 = time.perf_counter()
    staged = torch.empty((v, h, w), dtype=torch.int16).pin_memory()
    for i in range(v):
        lab = np.asarray(labels[i]).astype(np.int32)
        bad = (lab != no_label) & ((lab < 0) | (lab >= k_classes))
        if bad.any():
            sys.exit(f"view {i}: label ids outside 0..{k_classes - 1}")
        lab[lab == no_label] = k_classes
        staged[i].copy_(torch.from_numpy(lab.astype(np.int16)))
    log(f"labels staged in {time.perf_counter() - t0:.2f}s (not timed)")

    def view_counts(i):
        gt_mask = staged[i].to(dev, non_blocking=True).float()
        out = GaussianRasterizer(raster_settings=settings[i])(
            means3D=means, means2D=means2d, opacities=opac, shs=shs, colors_precomp=None,
            scales=scales, rotations=rots, cov3D_precomp=None, gt_mask=gt_mask)
        return out[5]  # used_count [num_obj + 1, N]

    with torch.no_grad():
        uc = None
        for i in range(args.warmup):
            uc = view_counts(i % v)
        torch.cuda.synchronize()
        if uc is not None and tuple(uc.shape) != (num_obj + 1, n):
            sys.exit(f"used_count has shape {tuple(uc.shape)}, expected {(num_obj + 1, n)}")
        del uc
        torch.cuda.reset_peak_memory_stats()

        start = torch.cuda.Event(enable_timing=True)
        end = torch.cuda.Event(enable_timing=True)
        all_counts = None
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        start.record()
        for i in range(v):
            used_count = view_counts(i)
            if all_counts is None:
                all_counts = torch.zeros_like(used_count)
            all_counts += used_count
        end.record()
        torch.cuda.synchronize()
        accumulate_s = time.perf_counter() - t0
        accumulate_gpu_ms = start.elapsed_time(end)
        log(f"accumulate: {accumulate_s:.3f}s wall, {accumulate_gpu_ms:.2f} ms GPU, "
            f"{v / accumulate_s:.1f} views/s")

        t0 = time.perf_counter()
        obj_labels = multi_instance_opt(all_counts, 0.0)
        torch.cuda.synchronize()
        assign_s = time.perf_counter() - t0
        del obj_labels
        t0 = time.perf_counter()
        evidence = all_counts[:k_classes].sum(dim=0) > 0
        classes = torch.where(evidence, all_counts[:k_classes].argmax(dim=0),
                              torch.full_like(evidence, -1, dtype=torch.long))
        torch.cuda.synchronize()
        assign_argmax_s = time.perf_counter() - t0
        log(f"assign: multi_instance_opt {assign_s:.4f}s, argmax {assign_argmax_s:.4f}s; "
            f"{int(evidence.sum())} of {n} Gaussians have evidence")
        if args.save_classes:
            np.save(args.save_classes, classes.to(torch.int32).cpu().numpy())
            log(f"wrote {args.save_classes}")

    doc = {
        "tool": "flashsplat",
        "commit": args.commit,
        "device": torch.cuda.get_device_name(),
        "torch": torch.__version__,
        "cuda": torch.version.cuda,
        "scene": args.label or os.path.basename(os.path.normpath(args.scene)),
        "n": n,
        "sh_degree": g["sh_degree"],
        "views": v,
        "width": w,
        "height": h,
        "classes": k_classes,
        "num_obj": num_obj,
        "accumulate_s": accumulate_s,
        "accumulate_gpu_ms": accumulate_gpu_ms,
        "views_per_s": v / accumulate_s,
        "assign_s": assign_s,
        "assign_method": "multi_instance_opt (FlashSplat render.py, slackness 0, "
                         f"over all {num_obj + 1} rows incl. unlabeled)",
        "assign_argmax_s": assign_argmax_s,
        "gaussians_with_evidence": int(evidence.sum()),
        "peak_mem_bytes": int(torch.cuda.max_memory_allocated()),
        "notes": [
            "accumulate: per view upload of the label map (pinned host int16, unlabeled "
            "mapped to K beforehand) + .float() + FlashSplat render with gt_mask + "
            "all_counts += used_count; synchronized once at the end; warm-up view untimed",
            "peak_mem_bytes: torch.cuda.max_memory_allocated() since the warm-up",
            "INRIA conventions: alpha clamp 0.99, eps2d 0.3 fixed, near cull z <= 0.2",
        ],
    }
    if args.out:
        runs = []
        if os.path.exists(args.out):
            try:
                with open(args.out) as f:
                    old = json.load(f)
                runs = old if isinstance(old, list) else [old]
            except (OSError, ValueError):
                runs = []
        runs.append(doc)
        with open(args.out + ".tmp", "w") as f:
            json.dump(runs, f, indent=2)
        os.replace(args.out + ".tmp", args.out)
        log(f"wrote {args.out}")
    else:
        print(json.dumps(doc, indent=2))


if __name__ == "__main__":
    main()
