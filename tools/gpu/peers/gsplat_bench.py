"""gsplat speed on a semsplat bench export: forward, forward+backward and one training
iteration, for RGB + C semantic channels blended in one pass (what semsplat renders).

  TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=16 PYTHONPATH=/tmp/gsplat_site:tools/gpu/peers \
    python3 tools/gpu/peers/gsplat_bench.py --scene DIR --channels 0,16,32,64 \
      --iters 10 --warmup 3 --label office --out gsplat.json

Per C in --channels:
  forward   C = 0: gsplat's own SH path (colors = SH coeffs [N,K,3], sh_degree = degree).
            C > 0: spherical_harmonics(degree, means - campos, sh) -> clamp(rgb + 0.5, 0),
            concatenated with C fixed random logits -> colors [N, 3+C], sh_degree=None.
            rasterization(..., eps2d=0.3, near, far, classic, black background, packed=False
            unless --packed). gsplat renders channels in chunks of --channel-chunk (its
            default 32) and pads each chunk to a supported width (e.g. 19 -> 32).
  backward  the same with grads on means, quats, scales, opacities, SH/colors and logits;
            loss = (render_colors * G).sum() + (render_alphas * Ga).sum().
  train     leaf params (means, quats, log scales, opacity logits, SH, logits), Adam
            (fused when available); loss = L1(rgb, target) + CE(logits, target labels);
            forward + loss + backward + step. "full" trains everything; "semantics_only"
            (C > 0) trains the logits alone with the same forward and loss.
Times are CUDA-event medians over --iters after --warmup, synchronized; wall medians too.
"""

import argparse
import json
import math
import os
import statistics
import sys
import time
import traceback

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scene_io  # noqa: E402


def log(*a):
    print(*a, flush=True)


# ----------------------------------------------------------------------------- timing


def time_events(fn, iters, warmup, marks=1):
    """Runs fn() warmup + iters times. fn receives a list of `marks - 1` CUDA events to
    record at its inner points (e.g. after the forward). Returns lists of per-iteration
    milliseconds: segments[k] = from mark k to k+1 (mark 0 = start, last = end), plus
    'total' and 'wall'."""
    # At least `warmup` runs and WARMUP_S seconds (as semsplat's benchmarks): an idle GPU
    # takes a while to reach its working clocks.
    t_warm = time.perf_counter()
    done = 0
    while done < warmup or time.perf_counter() - t_warm < WARMUP_S:
        fn([torch.cuda.Event(enable_timing=True) for _ in range(marks - 1)])
        torch.cuda.synchronize()
        done += 1
    seg = [[] for _ in range(marks)]
    total, wall = [], []
    for _ in range(iters):
        start = torch.cuda.Event(enable_timing=True)
        end = torch.cuda.Event(enable_timing=True)
        inner = [torch.cuda.Event(enable_timing=True) for _ in range(marks - 1)]
        t0 = time.perf_counter()
        start.record()
        fn(inner)
        end.record()
        end.synchronize()
        wall.append((time.perf_counter() - t0) * 1e3)
        evs = [start] + inner + [end]
        for k in range(marks):
            seg[k].append(evs[k].elapsed_time(evs[k + 1]))
        total.append(start.elapsed_time(end))
    return {"segments": seg, "total": total, "wall": wall}


WARMUP_S = 0.5


def med(xs):
    return float(statistics.median(xs))


# ----------------------------------------------------------------------------- render


class Bench:
    def __init__(self, args):
        from gsplat.rendering import rasterization
        from gsplat.cuda._wrapper import spherical_harmonics
        self.rasterization = rasterization
        self.spherical_harmonics = spherical_harmonics
        self.args = args
        dev = torch.device("cuda")
        self.dev = dev

        g = scene_io.load_gaussians(os.path.join(args.scene, "scene.ply"))
        self.bench = scene_io.read_bench(args.scene)
        cams = scene_io.read_cameras(os.path.join(args.scene, "cameras.json"))
        self.n = g["n"]
        self.degree = g["sh_degree"]
        self.near = float(self.bench.get("near", 0.01))
        self.far = float(self.bench.get("far", 1e10))
        self.means = torch.from_numpy(g["means"]).to(dev)
        self.quats = torch.from_numpy(g["quats"]).to(dev)
        self.scales = torch.from_numpy(g["scales"]).to(dev)
        self.opacities = torch.from_numpy(g["opacities"]).to(dev)
        self.sh = torch.from_numpy(g["sh"]).to(dev).contiguous()  # [N,K,3]
        self.width = int(cams["widths"][0])
        self.height = int(cams["heights"][0])
        if not (np.all(cams["widths"] == self.width) and np.all(cams["heights"] == self.height)):
            raise ValueError("all cameras must share one image size")
        views = range(len(cams["names"])) if args.all_views else [0]
        self.viewmats = [torch.from_numpy(cams["viewmats"][i]).to(dev)[None] for i in views]
        self.Ks = [torch.from_numpy(cams["Ks"][i]).to(dev)[None] for i in views]
        self.campos = [torch.from_numpy(scene_io.camera_center(cams["viewmats64"][i])
                                        .astype(np.float32)).to(dev) for i in views]
        self.view = 0
        log(f"scene: N={self.n} SH degree {self.degree} {self.width}x{self.height}, "
            f"{len(self.viewmats)} view(s) timed, near {self.near} far {self.far}")

    def next_view(self):
        i = self.view
        self.view = (self.view + 1) % len(self.viewmats)
        return self.viewmats[i], self.Ks[i], self.campos[i]

    def render(self, means, quats, scales, opacities, sh, logits, view):
        """One frame: RGB (SH) + the logits' channels in one blend. logits None -> gsplat's
        own SH path. Returns (render_colors [1,H,W,D], render_alphas [1,H,W,1], meta)."""
        viewmat, k, campos = view
        common = dict(near_plane=self.near, far_plane=self.far, eps2d=0.3,
                      packed=self.args.packed, rasterize_mode="classic",
                      channel_chunk=self.args.channel_chunk, render_mode="RGB")
        if logits is None:
            return self.rasterization(means, quats, scales, opacities, sh, viewmat, k,
                                      self.width, self.height, sh_degree=self.degree, **common)
        dirs = means - campos[None, :]
        rgb = self.spherical_harmonics(self.degree, dirs, sh)
        rgb = torch.clamp_min(rgb + 0.5, 0.0)
        colors = torch.cat([rgb, logits], dim=-1)
        return self.rasterization(means, quats, scales, opacities, colors, viewmat, k,
                                  self.width, self.height, sh_degree=None, **common)

    # ------------------------------------------------------------------------- cases

    def logits_for(self, c):
        if c == 0:
            return None
        gen = torch.Generator(device="cpu").manual_seed(1234 + c)
        return torch.randn(self.n, c, generator=gen).to(self.dev)

    def forward(self, c):
        logits = self.logits_for(c)
        out = {}

        def fn(_marks):
            with torch.no_grad():
                self.render(self.means, self.quats, self.scales, self.opacities, self.sh,
                            logits, self.next_view())

        t = time_events(fn, self.args.iters, self.args.warmup)
        out["forward_ms"] = med(t["total"])
        out["forward_wall_ms"] = med(t["wall"])
        with torch.no_grad():
            _, _, meta = self.render(self.means, self.quats, self.scales, self.opacities,
                                     self.sh, logits, self.next_view())
            out.update(meta_counts(meta))
        return out

    def backward(self, c):
        means = self.means.clone().requires_grad_(True)
        quats = self.quats.clone().requires_grad_(True)
        scales = self.scales.clone().requires_grad_(True)
        opac = self.opacities.clone().requires_grad_(True)
        sh = self.sh.clone().requires_grad_(True)
        logits = self.logits_for(c)
        if logits is not None:
            logits.requires_grad_(True)
        leaves = [means, quats, scales, opac, sh] + ([logits] if logits is not None else [])
        gen = torch.Generator(device="cpu").manual_seed(99 + c)
        g_col = torch.randn(1, self.height, self.width, 3 + c, generator=gen).to(self.dev)
        g_alpha = torch.randn(1, self.height, self.width, 1, generator=gen).to(self.dev)

        def fn(marks):
            for p in leaves:
                p.grad = None
            colors, alphas, _ = self.render(means, quats, scales, opac, sh, logits,
                                            self.next_view())
            loss = (colors * g_col).sum() + (alphas * g_alpha).sum()
            marks[0].record()
            loss.backward()

        t = time_events(fn, self.args.iters, self.args.warmup, marks=2)
        fwd, bwd_only = t["segments"]
        out = {
            "fwd_bwd_ms": med(t["total"]),
            "forward_grad_ms": med(fwd),
            "backward_ms": med(t["total"]) - med(fwd),
            "backward_only_ms": med(bwd_only),
            "fwd_bwd_wall_ms": med(t["wall"]),
        }
        del means, quats, scales, opac, sh, logits, leaves
        return out

    def train(self, c, semantics_only):
        """One training iteration per call: forward, L1 (+ CE), backward, Adam step."""
        dev = self.dev
        logits = self.logits_for(c)
        means = self.means.clone()
        quats = self.quats.clone()
        log_scales = torch.log(self.scales)
        opac_logits = torch.logit(self.opacities.clamp(1e-6, 1 - 1e-6))
        sh = self.sh.clone()
        if semantics_only:
            params = [logits]
        else:
            params = [means, quats, log_scales, opac_logits, sh] + (
                [logits] if logits is not None else [])
        for p in params:
            p.requires_grad_(True)
        lrs = {id(means): 1.6e-4, id(quats): 1e-3, id(log_scales): 5e-3,
               id(opac_logits): 5e-2, id(sh): 2.5e-3}
        groups = [{"params": [p], "lr": lrs.get(id(p), 1e-2)} for p in params]
        try:
            opt = torch.optim.Adam(groups, eps=1e-15, fused=True)
            fused = True
        except (TypeError, RuntimeError, ValueError):
            opt = torch.optim.Adam(groups, eps=1e-15)
            fused = False
        gen = torch.Generator(device="cpu").manual_seed(7 + c)
        target_rgb = torch.rand(self.height, self.width, 3, generator=gen).to(dev)
        target_lab = (torch.randint(0, c, (self.height * self.width,), generator=gen).to(dev)
                      if c > 0 else None)

        def fn(_marks):
            opt.zero_grad(set_to_none=True)
            colors, _alphas, _ = self.render(
                means, quats, torch.exp(log_scales),
                torch.sigmoid(opac_logits), sh, logits, self.next_view())
            img = colors[0]
            loss = (img[..., :3] - target_rgb).abs().mean()
            if c > 0:
                loss = loss + F.cross_entropy(img[..., 3:].reshape(-1, c), target_lab)
            loss.backward()
            opt.step()

        t = time_events(fn, self.args.iters, self.args.warmup)
        del opt, params, groups, means, quats, log_scales, opac_logits, sh, logits
        return med(t["total"]), med(t["wall"]), fused


def meta_counts(meta):
    """Visible Gaussians (radii > 0 in both axes) and tile intersections, from gsplat's
    meta (gsplat 1.5: radii int32 [..., C, N, 2] or [nnz, 2]; isect_ids [n_isects])."""
    out = {}
    try:
        radii = meta["radii"]
        vis = (radii > 0).all(dim=-1) if radii.dim() >= 2 and radii.shape[-1] == 2 else radii > 0
        out["visible"] = int(vis.sum().item())
    except Exception as e:  # noqa: BLE001
        out["visible_error"] = repr(e)
    try:
        out["intersections"] = int(meta["isect_ids"].numel())
    except Exception as e:  # noqa: BLE001
        out["intersections_error"] = repr(e)
    return out


def attempt(res, name, fn):
    """Runs one measurement; an exception (OOM, ...) is recorded, not fatal."""
    try:
        return fn()
    except Exception as e:  # noqa: BLE001
        log(f"  {name} FAILED: {e!r}")
        traceback.print_exc()
        res.setdefault("errors", {})[name] = repr(e)
        return None
    finally:
        try:
            torch.cuda.synchronize()
            torch.cuda.empty_cache()
        except Exception as e:  # noqa: BLE001  (a sticky CUDA error: the rest will fail too)
            log(f"  after {name}: {e!r}")


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", required=True, help="semsplat bench --export folder")
    ap.add_argument("--channels", default="0,16,32,64", help="comma-separated C values")
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--out", help="JSON file; an existing one with a list of results "
                    "(or one result) is kept and this run appended")
    ap.add_argument("--label", default=None, help="scene label in the JSON")
    ap.add_argument("--all-views", action="store_true",
                    help="cycle through all cameras instead of timing the first")
    ap.add_argument("--packed", action="store_true", help="gsplat packed mode "
                    "(default: packed=False, gsplat's faster mode)")
    ap.add_argument("--channel-chunk", type=int, default=32,
                    help="gsplat's channel_chunk (its default 32)")
    ap.add_argument("--skip", default="", help="comma list of forward,backward,train to skip")
    args = ap.parse_args()
    channels = [int(x) for x in args.channels.split(",") if x.strip() != ""]
    skip = set(s.strip() for s in args.skip.split(",") if s.strip())

    if not torch.cuda.is_available():
        sys.exit("CUDA is not available")
    t0 = time.perf_counter()
    import gsplat
    from gsplat.cuda import _backend
    if _backend._C is None:
        sys.exit("gsplat's CUDA extension did not load (see the messages above)")
    log(f"gsplat {gsplat.__version__}: CUDA extension ready in {time.perf_counter() - t0:.1f}s")

    bench = Bench(args)
    doc = {
        "tool": "gsplat",
        "version": gsplat.__version__,
        "device": torch.cuda.get_device_name(),
        "torch": torch.__version__,
        "cuda": torch.version.cuda,
        "scene": args.label or os.path.basename(os.path.normpath(args.scene)),
        "n": bench.n,
        "sh_degree": bench.degree,
        "width": bench.width,
        "height": bench.height,
        "views_timed": len(bench.viewmats),
        "iters": args.iters,
        "warmup": args.warmup,
        "packed": args.packed,
        "channel_chunk": args.channel_chunk,
        "loss": "L1 + CE",
        "notes": [
            "times are CUDA-event medians in ms (the *_wall_ms fields: host wall clock)",
            "C = 0 uses gsplat's SH path (sh_degree set); C > 0 evaluates SH with "
            "gsplat.cuda._wrapper.spherical_harmonics for all N Gaussians and blends "
            "3 + C channels in one rasterization call (chunked by channel_chunk)",
            "backward_ms = median(fwd_bwd) - median(forward with grad); "
            "backward_only_ms = median of the backward segment alone",
            "train: forward + loss + backward + Adam step; loss L1 + CE, no SSIM "
            "(semsplat's full iteration also computes SSIM); semantics_only trains the "
            "logits alone with the same forward and loss",
            "eps2d 0.3, classic mode, black background, alpha clamp 0.999 (gsplat's)",
        ],
        "results": [],
    }

    for c in channels:
        log(f"C={c}")
        res = {"channels": c}
        if "forward" not in skip:
            r = attempt(res, "forward", lambda: bench.forward(c))
            if r:
                res.update(r)
                log(f"  forward {r['forward_ms']:.3f} ms  visible {r.get('visible')} "
                    f"intersections {r.get('intersections')}")
        if "backward" not in skip:
            r = attempt(res, "backward", lambda: bench.backward(c))
            if r:
                res.update(r)
                log(f"  fwd+bwd {r['fwd_bwd_ms']:.3f} ms (forward with grad "
                    f"{r['forward_grad_ms']:.3f}, backward {r['backward_ms']:.3f})")
        if "train" not in skip:
            r = attempt(res, "train_full", lambda: bench.train(c, False))
            if r:
                res["train_iter_ms"], res["train_iter_wall_ms"], res["adam_fused"] = r
                log(f"  train iteration (full) {r[0]:.3f} ms")
            if c > 0:
                r = attempt(res, "train_semantics_only", lambda: bench.train(c, True))
                if r:
                    res["train_iter_semantics_only_ms"] = r[0]
                    res["train_iter_semantics_only_wall_ms"] = r[1]
                    log(f"  train iteration (semantics only) {r[0]:.3f} ms")
        res["peak_mem_bytes"] = int(torch.cuda.max_memory_allocated())
        torch.cuda.reset_peak_memory_stats()
        doc["results"].append(res)
        torch.cuda.empty_cache()
        if args.out:
            write_out(args.out, doc)

    if args.out:
        write_out(args.out, doc)
        log(f"wrote {args.out}")
    else:
        print(json.dumps(doc, indent=2))


def write_out(path, doc):
    """Appends doc to the list of runs in path (replacing this run's earlier partial copy),
    atomically."""
    runs = []
    if os.path.exists(path):
        try:
            with open(path) as f:
                old = json.load(f)
            runs = old if isinstance(old, list) else [old]
        except (OSError, ValueError):
            runs = []
    run_id = doc.setdefault("run_id", f"{time.time():.6f}-{os.getpid()}")
    runs = [r for r in runs if not (isinstance(r, dict) and r.get("run_id") == run_id)]
    runs.append(doc)
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(runs, f, indent=2)
    os.replace(tmp, path)


if __name__ == "__main__":
    main()
