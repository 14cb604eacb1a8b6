"""Checks scene_io.py without a GPU (numpy only).

  python3 tools/gpu/peers/check_scene_io.py --scene DIR

DIR: a semsplat export (`bench --export`) or synth output (scene.ply + cameras.json).
Checks:
  1. scene.ply parses (N, property names, SH degree, semantic channels, finite values).
  2. A synthetic PLY (SH degree 3, sem_*, an int and a uchar property) written here
     round-trips: f_rest channel-major -> sh[N,16,3], activations, sem order.
  3. Cameras: viewmats are rigid (R orthonormal, det +1, last row 0 0 0 1), Ks as given;
     projecting the Gaussian centers with K (R x + t) puts most of the ones in front of
     each camera inside the image.
  4. INRIA path (FlashSplat): full_proj_transform + ndc2Pix gives, + 0.5, the same pixel
     as the K path to 1e-3 px (float32 math, as the CUDA code), and campos = -R^T t.
Exit status 1 on a failed check.
"""

import argparse
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scene_io  # noqa: E402

FAILED = []


def check(cond, msg):
    print(("ok    " if cond else "FAIL  ") + msg, flush=True)
    if not cond:
        FAILED.append(msg)


def write_test_ply(path, n, rng):
    """A PLY laid out the way INRIA / semsplat write it, plus extra properties."""
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(45)]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    fields = [(nm, "<f4") for nm in names] + [("class", "<i4")]
    fields += [(f"sem_{i}", "<f4") for i in range(4)] + [("flag", "u1")]
    arr = np.zeros(n, dtype=np.dtype(fields))
    for nm in names:
        arr[nm] = rng.normal(size=n).astype(np.float32)
    arr["class"] = rng.integers(0, 10, n)
    for i in range(4):
        arr[f"sem_{i}"] = rng.normal(size=n).astype(np.float32)
    arr["flag"] = 7
    ply_types = {"<f4": "float", "<i4": "int", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment test",
              f"element vertex {n}"]
    header += [f"property {ply_types[dt]} {nm}" for nm, dt in fields]
    header += ["end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(arr.tobytes())
    return arr


def check_synthetic(rng):
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "t.ply")
        raw = write_test_ply(path, 257, rng)
        g = scene_io.load_gaussians(path)
    check(g["n"] == 257 and g["sh_degree"] == 3 and g["sh"].shape == (257, 16, 3),
          f"synthetic PLY: n={g['n']} degree={g['sh_degree']} sh {g['sh'].shape}")
    i = 5
    ok = np.isclose(g["sh"][i, 0, 1], raw["f_dc_1"][i])
    # coefficient j (1..15) of channel c is f_rest_{c*15 + j-1}
    for c in range(3):
        for j in range(1, 16):
            ok &= np.isclose(g["sh"][i, j, c], raw[f"f_rest_{c * 15 + j - 1}"][i])
    check(bool(ok), "synthetic PLY: f_rest channel-major -> sh[:, 1:, c]")
    check(np.allclose(g["sem"][:, 2], raw["sem_2"]) and g["sem"].shape == (257, 4),
          "synthetic PLY: sem_* in order")
    check(np.allclose(np.linalg.norm(g["quats"], axis=1), 1, atol=1e-5)
          and np.allclose(g["quats"][i] * np.linalg.norm(
              [raw[f"rot_{k}"][i] for k in range(4)]), [raw[f"rot_{k}"][i] for k in range(4)],
              atol=1e-5),
          "synthetic PLY: quaternions normalized, w first")
    check(np.allclose(g["scales"][:, 0], np.exp(raw["scale_0"]), rtol=1e-5)
          and np.allclose(g["opacities"], 1 / (1 + np.exp(-raw["opacity"].astype(np.float64))),
                          atol=1e-6),
          "synthetic PLY: scales exp, opacity sigmoid")
    check(np.array_equal(g["means"][:, 2], raw["z"]), "synthetic PLY: means")


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", required=True, help="folder with scene.ply and cameras.json")
    args = ap.parse_args()
    rng = np.random.default_rng(0)

    check_synthetic(rng)

    g = scene_io.load_gaussians(os.path.join(args.scene, "scene.ply"))
    n = g["n"]
    sem = None if g["sem"] is None else g["sem"].shape[1]
    print(f"scene.ply: N={n}, SH degree {g['sh_degree']}, semantic channels {sem}")
    print(f"  properties: {' '.join(g['names'])}")
    check(n > 0, "scene.ply has Gaussians")
    check(all(np.isfinite(g[k]).all() for k in ("means", "quats", "scales", "opacities", "sh")),
          "scene.ply values finite")
    bench = scene_io.read_bench(args.scene)
    if bench:
        print(f"bench.json: {bench}")
        check(bench.get("n") == n, "bench.json n matches the PLY")
        check(bench.get("channels", 0) == (sem or 0), "bench.json channels match sem_*")
        check(bench.get("sh_degree", g["sh_degree"]) == g["sh_degree"],
              "bench.json sh_degree matches f_rest")

    cams = scene_io.read_cameras(os.path.join(args.scene, "cameras.json"))
    v = len(cams["names"])
    print(f"cameras.json: {v} cameras, first {cams['names'][0]} "
          f"{cams['widths'][0]}x{cams['heights'][0]} fx={cams['fx'][0]:.3f}")
    for i in range(v):
        vm = cams["viewmats64"][i]
        r = vm[:3, :3]
        check(np.allclose(r @ r.T, np.eye(3), atol=1e-5) and abs(np.linalg.det(r) - 1) < 1e-5
              and np.allclose(vm[3], [0, 0, 0, 1]), f"camera {i}: rigid world->camera")
        check(np.allclose(cams["Ks"][i], [[cams["fx"][i], 0, cams["cx"][i]],
                                          [0, cams["fy"][i], cams["cy"][i]], [0, 0, 1]]),
              f"camera {i}: K")
        w, h = int(cams["widths"][i]), int(cams["heights"][i])

        uv, z = scene_io.k_project(g["means"], vm, cams["Ks"][i])
        front = z > 0.2
        inside = front & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        frac = inside.sum() / max(front.sum(), 1)
        print(f"  camera {i}: {front.sum()} centers in front, {inside.sum()} inside "
              f"({100 * frac:.1f}% of those in front)")
        check(inside.sum() > 0.1 * n or frac > 0.5, f"camera {i}: many centers land in the image")

        ic = scene_io.inria_camera(vm, cams["fx"][i], cams["fy"][i], cams["cx"][i],
                                   cams["cy"][i], w, h, znear=bench.get("near", 0.01),
                                   zfar=bench.get("far", 1e10))
        sel = np.flatnonzero(inside)[:200]
        if sel.size == 0:
            sel = np.flatnonzero(front)[:200]
        pix_inria = scene_io.inria_project(g["means"][sel], ic["full_proj_transform"], w, h)
        err = np.abs(pix_inria + 0.5 - uv[sel]).max() if sel.size else 0.0
        print(f"  camera {i}: INRIA full_proj + ndc2Pix + 0.5 vs K path: max |diff| "
              f"{err:.2e} px over {sel.size} points")
        check(err < 1e-3, f"camera {i}: INRIA and K projections agree to 1e-3 px")
        # also with INRIA's own zfar (100, as FlashSplat's Camera uses)
        ic100 = scene_io.inria_camera(vm, cams["fx"][i], cams["fy"][i], cams["cx"][i],
                                      cams["cy"][i], w, h, znear=0.01, zfar=100.0)
        pix100 = scene_io.inria_project(g["means"][sel], ic100["full_proj_transform"], w, h)
        check(np.abs(pix100 - pix_inria).max() < 1e-3 if sel.size else True,
              f"camera {i}: pixels do not depend on znear/zfar")
        # world_view_transform^T is the viewmat; campos is the camera center
        check(np.allclose(ic["world_view_transform"].T, vm, atol=1e-6), f"camera {i}: W2C^T")
        cp = ic["campos"].astype(np.float64)
        check(np.allclose(vm[:3, :3] @ cp + vm[:3, 3], 0, atol=1e-4), f"camera {i}: campos")
        # INRIA derives campos as inverse(world_view_transform)[3, :3]
        check(np.allclose(np.linalg.inv(ic["world_view_transform"].astype(np.float64))[3, :3],
                          cp, atol=1e-4), f"camera {i}: campos as INRIA computes it")

    labels_path = os.path.join(args.scene, "labels.npy")
    if os.path.exists(labels_path):
        lab = np.load(labels_path, mmap_mode="r")
        print(f"labels.npy: {lab.dtype} {lab.shape}")
        check(lab.dtype == np.uint16 and lab.shape == (v, int(cams["heights"][0]),
                                                       int(cams["widths"][0])),
              "labels.npy is uint16 [V, H, W]")

    if FAILED:
        print(f"{len(FAILED)} check(s) failed")
        sys.exit(1)
    print("all checks passed")


if __name__ == "__main__":
    main()
