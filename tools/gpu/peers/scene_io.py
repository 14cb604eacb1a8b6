"""Readers for the files `semsplat bench ... --export DIR` writes, shared by the peer
benchmarks (gsplat_bench.py, flashsplat_bench.py) and check_scene_io.py.

numpy only (no torch here), so it can be checked on a machine without a GPU.

Files in an export folder:
  scene.ply     INRIA 3DGS PLY (binary_little_endian), one `vertex` element:
                x y z nx ny nz f_dc_0..2 [f_rest_0..] opacity scale_0..2 rot_0..3 [sem_0..]
                and possibly other properties (e.g. `int class`), which are ignored.
  cameras.json  {"cameras": [{"width","height","fx","fy","cx","cy","world_to_camera"}...]}
                world_to_camera: world -> camera, OpenCV axes (x right, y down, z forward).
  labels.npy    uint16 [V, H, W], one label map per camera; bench.json "no_label"
                (65535) marks unlabeled pixels.
  bench.json    {"n","channels","classes","width","height","views","near","far","sh_degree"}
"""

import json
import math
import os

import numpy as np

# PLY scalar type names -> numpy little-endian dtypes.
_PLY_TYPES = {
    "char": "i1", "int8": "i1",
    "uchar": "u1", "uint8": "u1",
    "short": "<i2", "int16": "<i2",
    "ushort": "<u2", "uint16": "<u2",
    "int": "<i4", "int32": "<i4",
    "uint": "<u4", "uint32": "<u4",
    "float": "<f4", "float32": "<f4",
    "double": "<f8", "float64": "<f8",
}

NO_LABEL = 65535


# ----------------------------------------------------------------------------- PLY


def read_ply_vertices(path):
    """Returns the `vertex` element of a binary little-endian PLY as a numpy structured
    array (one field per property, named as in the header)."""
    with open(path, "rb") as f:
        magic = f.readline()
        if magic.strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file")
        elements = []  # [(name, count, [(prop_name, dtype)])]
        fmt = None
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: no end_header")
            words = line.decode("ascii", "replace").split()
            if not words:
                continue
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                elements.append((words[1], int(words[2]), []))
            elif words[0] == "property":
                if not elements:
                    raise ValueError(f"{path}: property before any element")
                if words[1] == "list":
                    # A list property makes records variable-sized; INRIA vertex
                    # elements never have one.
                    elements[-1][2].append((words[-1], None))
                else:
                    if words[1] not in _PLY_TYPES:
                        raise ValueError(f"{path}: unknown PLY type {words[1]}")
                    elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
            elif words[0] == "end_header":
                break
            # comment / obj_info lines are skipped
        header_end = f.tell()
    if fmt != "binary_little_endian":
        raise ValueError(f"{path}: format {fmt}, only binary_little_endian is supported")

    offset = header_end
    for name, count, props in elements:
        if any(dt is None for _, dt in props):
            if name == "vertex":
                raise ValueError(f"{path}: list property in the vertex element")
            raise ValueError(f"{path}: list property in element {name} before vertex")
        dtype = np.dtype([(pname, dt) for pname, dt in props])
        if name == "vertex":
            data = np.fromfile(path, dtype=dtype, count=count, offset=offset)
            if data.shape[0] != count:
                raise ValueError(f"{path}: file holds {data.shape[0]} of {count} vertices")
            return data
        offset += count * dtype.itemsize
    raise ValueError(f"{path}: no vertex element")


def _numbered(names, prefix):
    """Field names prefix0..prefixK-1 in numeric order (checked contiguous)."""
    idx = sorted(int(n[len(prefix):]) for n in names
                 if n.startswith(prefix) and n[len(prefix):].isdigit())
    if idx != list(range(len(idx))):
        raise ValueError(f"properties {prefix}* are not numbered 0..{len(idx) - 1}")
    return [f"{prefix}{i}" for i in idx]


def _stack(v, fields):
    return np.stack([np.asarray(v[f], dtype=np.float32) for f in fields], axis=1)


def load_gaussians(path):
    """Loads an INRIA 3DGS PLY and activates it.

    Returns a dict of numpy float32 arrays:
      means [N,3]; quats [N,4] (w,x,y,z, normalized); scales [N,3] (exp of the log scales);
      opacities [N] (sigmoid of the logits); sh [N,K,3] with K=(sh_degree+1)^2, coefficient
      index major, RGB minor (gsplat's and INRIA's `get_features` layout); sh_degree (int);
      sem [N,C] semantic logits or None; names (property names).
    """
    v = read_ply_vertices(path)
    names = list(v.dtype.names)
    n = v.shape[0]
    means = _stack(v, ["x", "y", "z"])
    rots = _stack(v, ["rot_0", "rot_1", "rot_2", "rot_3"])  # w, x, y, z
    norm = np.linalg.norm(rots, axis=1, keepdims=True)
    quats = rots / np.maximum(norm, 1e-12)
    scales = np.exp(_stack(v, ["scale_0", "scale_1", "scale_2"]))
    opac_logit = np.asarray(v["opacity"], dtype=np.float64)
    opacities = (1.0 / (1.0 + np.exp(-opac_logit))).astype(np.float32)

    dc = _stack(v, ["f_dc_0", "f_dc_1", "f_dc_2"])  # [N,3]
    rest_fields = _numbered(names, "f_rest_")
    if len(rest_fields) % 3 != 0:
        raise ValueError(f"{len(rest_fields)} f_rest properties is not a multiple of 3")
    k = 1 + len(rest_fields) // 3
    degree = int(round(math.sqrt(k))) - 1
    if (degree + 1) ** 2 != k:
        raise ValueError(f"{len(rest_fields)} f_rest properties fit no SH degree")
    sh = np.empty((n, k, 3), dtype=np.float32)
    sh[:, 0, :] = dc
    if k > 1:
        # INRIA writes f_rest channel-major: f_rest_0..k-2 are red coefficients 1..k-1,
        # then green, then blue. [N, 3, k-1] -> [N, k-1, 3].
        rest = _stack(v, rest_fields).reshape(n, 3, k - 1)
        sh[:, 1:, :] = rest.transpose(0, 2, 1)

    sem_fields = _numbered(names, "sem_")
    sem = _stack(v, sem_fields) if sem_fields else None
    return {
        "n": n, "means": means, "quats": quats.astype(np.float32),
        "scales": scales.astype(np.float32), "opacities": opacities,
        "sh": sh, "sh_degree": degree, "sem": sem, "names": names,
    }


# ----------------------------------------------------------------------------- cameras


def read_cameras(path):
    """Reads semsplat camera JSON. Returns a dict:
      names [V]; widths, heights [V] int; fx, fy, cx, cy [V] float64;
      viewmats [V,4,4] float32 (world -> camera, OpenCV; gsplat's `viewmats`);
      Ks [V,3,3] float32 ([[fx,0,cx],[0,fy,cy],[0,0,1]]; gsplat's `Ks`); splits [V].
    """
    with open(path) as f:
        doc = json.load(f)
    cams = doc["cameras"] if isinstance(doc, dict) else doc
    if not cams:
        raise ValueError(f"{path}: no cameras")
    v = len(cams)
    out = {
        "names": [c.get("name", f"view_{i}") for i, c in enumerate(cams)],
        "splits": [c.get("split", "") for c in cams],
        "widths": np.array([int(c["width"]) for c in cams]),
        "heights": np.array([int(c["height"]) for c in cams]),
    }
    for k in ("fx", "fy", "cx", "cy"):
        out[k] = np.array([float(c[k]) for c in cams], dtype=np.float64)
    viewmats = np.array([c["world_to_camera"] for c in cams], dtype=np.float64)
    if viewmats.shape != (v, 4, 4):
        raise ValueError(f"{path}: world_to_camera must be 4x4, got {viewmats.shape[1:]}")
    ks = np.zeros((v, 3, 3), dtype=np.float64)
    ks[:, 0, 0] = out["fx"]
    ks[:, 1, 1] = out["fy"]
    ks[:, 0, 2] = out["cx"]
    ks[:, 1, 2] = out["cy"]
    ks[:, 2, 2] = 1.0
    out["viewmats64"] = viewmats
    out["viewmats"] = viewmats.astype(np.float32)
    out["Ks"] = ks.astype(np.float32)
    return out


def camera_center(viewmat):
    """World position of the camera of a world->camera matrix: -R^T t."""
    viewmat = np.asarray(viewmat, dtype=np.float64)
    r, t = viewmat[:3, :3], viewmat[:3, 3]
    return -r.T @ t


def read_bench(folder):
    """bench.json as a dict, or {} when the folder has none."""
    path = os.path.join(folder, "bench.json")
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        return json.load(f)


# ----------------------------------------------------------------------------- INRIA


def inria_projection_matrix(znear, zfar, tanfovx, tanfovy):
    """INRIA 3DGS's getProjectionMatrix (utils/graphics_utils.py), from the half-FOV
    tangents instead of the FOVs (same numbers), principal point at the image center.
    Row-major, maps camera coordinates to clip coordinates (w = z)."""
    top = tanfovy * znear
    bottom = -top
    right = tanfovx * znear
    left = -right
    p = np.zeros((4, 4), dtype=np.float64)
    p[0, 0] = 2.0 * znear / (right - left)
    p[1, 1] = 2.0 * znear / (top - bottom)
    p[0, 2] = (right + left) / (right - left)
    p[1, 2] = (top + bottom) / (top - bottom)
    p[3, 2] = 1.0
    p[2, 2] = zfar / (zfar - znear)
    p[2, 3] = -(zfar * znear) / (zfar - znear)
    return p


def inria_camera(viewmat, fx, fy, cx, cy, width, height, znear=0.01, zfar=100.0,
                 center_tol=0.5):
    """The camera as the INRIA / FlashSplat rasterizer takes it (numpy, float32):
      world_view_transform = W2C^T, full_proj_transform = (P @ W2C)^T (both as INRIA
      stores them: the CUDA code reads them as column-major 4x4), campos, tanfovx, tanfovy.
    INRIA has no principal point: it must be the image center (checked to center_tol px).

    Pixel convention: INRIA's pixel (i, j) is centered at coordinate (i, j) and its
    projected means are ndc2Pix(v, S) = ((v + 1) * S - 1) / 2; gsplat / OpenCV with
    cx = W/2 put pixel centers at i + 0.5. Both render the same image: INRIA's coordinate
    + 0.5 equals fx * x / z + cx (check_scene_io.py verifies this)."""
    if abs(cx - width / 2.0) > center_tol or abs(cy - height / 2.0) > center_tol:
        raise ValueError(
            f"INRIA-style rasterizers need the principal point at the image center; "
            f"got cx={cx}, cy={cy} for {width}x{height}")
    w2c = np.asarray(viewmat, dtype=np.float64)
    tanfovx = width / (2.0 * fx)
    tanfovy = height / (2.0 * fy)
    p = inria_projection_matrix(znear, zfar, tanfovx, tanfovy)
    return {
        "world_view_transform": w2c.T.astype(np.float32),
        "projection_matrix": p.T.astype(np.float32),
        "full_proj_transform": (p @ w2c).T.astype(np.float32),
        "campos": camera_center(w2c).astype(np.float32),
        "tanfovx": float(tanfovx),
        "tanfovy": float(tanfovy),
        "fovx": 2.0 * math.atan(tanfovx),
        "fovy": 2.0 * math.atan(tanfovy),
    }


def ndc_to_pix(v, size):
    """INRIA's ndc2Pix (cuda_rasterizer/auxiliary.h)."""
    return ((v + 1.0) * size - 1.0) * 0.5


def inria_project(points, full_proj_transform, width, height):
    """Projects world points [M,3] the way INRIA's preprocess does (transformPoint4x4 with
    the column-major full_proj_transform, i.e. row-vector [x y z 1] @ full_proj_transform,
    then divide by w, then ndc2Pix). Returns INRIA pixel coordinates [M,2] (float32 math,
    as on the GPU)."""
    pts = np.asarray(points, dtype=np.float32)
    hom = np.concatenate([pts, np.ones((pts.shape[0], 1), np.float32)], axis=1)
    clip = hom @ np.asarray(full_proj_transform, dtype=np.float32)
    w = clip[:, 3:4] + np.float32(1e-7)  # INRIA: p_w = 1 / (p_hom.w + 0.0000001)
    ndc = clip[:, :2] / w
    return np.stack([ndc_to_pix(ndc[:, 0], width), ndc_to_pix(ndc[:, 1], height)], axis=1)


def k_project(points, viewmat, k):
    """OpenCV / gsplat pinhole projection: K @ (R x + t), divided by z. Returns pixel
    coordinates [M,2] (pixel centers at i + 0.5) and camera-space depth z [M]."""
    pts = np.asarray(points, dtype=np.float64)
    vm = np.asarray(viewmat, dtype=np.float64)
    cam = pts @ vm[:3, :3].T + vm[:3, 3]
    z = cam[:, 2]
    uv = cam @ np.asarray(k, dtype=np.float64).T
    return uv[:, :2] / uv[:, 2:3], z
