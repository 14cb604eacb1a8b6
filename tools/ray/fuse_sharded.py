#!/usr/bin/env python3
"""View-sharded `semsplat fuse` on a Ray cluster, merged into what one `fuse` gives.

Each shard K of N is one Ray task running `semsplat fuse --shard K/N` (one GPU each where the
cluster has GPUs). The task returns its part (the exact integer evidence and its manifest)
through Ray's object store, or writes it straight into --parts with --shared-parts. A task
that fails (the CLI exits non-zero, or its worker dies) is retried up to --max-retries times
by Ray; a shard that still fails is named and the driver exits with status 2 without merging.
Then `semsplat merge` sums the parts and writes the outputs. See README.md beside this file.

Fault injection, for the tests only: SEMSPLAT_RAY_FAULT_SHARD=K makes shard K's first
SEMSPLAT_RAY_FAULT_TIMES attempts (default 1; "always" for every one) fail, by running the
CLI with an invalid --shard (SEMSPLAT_RAY_FAULT_MODE=exit, the default) or by killing the
task's worker process (=kill).
"""

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
try:
    import ray  # noqa: E402  (after the environment above)
except ModuleNotFoundError:
    # --help needs no Ray; a run does, and says so in one line rather than a traceback.
    ray = None


# The files a shard's part is: part<K>.npy and its manifest.
STALE_PART = re.compile(r"part\d+\.(npy|manifest\.json)")


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--shards", type=int, required=True, help="N: shards of the views")
    p.add_argument("--scene", required=True, help="scene PLY (same path on every node)")
    p.add_argument("--cameras", required=True, help="cameras (same path on every node)")
    p.add_argument("--labels", required=True, help="label folder (same path on every node)")
    p.add_argument("--out", required=True, help="the merged, labelled PLY")
    p.add_argument("--parts", required=True, help="folder for the parts on the driver")
    p.add_argument("--semsplat", default="semsplat", help="the CLI on every node")
    p.add_argument("--fuse-args", default="", help='extra fuse flags, e.g. "--method vote"')
    p.add_argument(
        "--merge-args", default="", help='extra merge outputs, e.g. "--palette-ply p.ply"'
    )
    p.add_argument("--address", default=None, help="Ray cluster address (default: local)")
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs of a local cluster")
    p.add_argument("--max-retries", type=int, default=2, help="retries of a failed shard")
    p.add_argument(
        "--shared-parts",
        action="store_true",
        help="tasks write parts straight into --parts (a folder every node sees)",
    )
    args = p.parse_args(argv)
    if args.shards < 1:
        p.error("--shards must be at least 1")
    # Workers may start in another folder: name local inputs absolutely.
    for name in ("scene", "cameras", "labels", "semsplat"):
        value = getattr(args, name)
        # A bare program name is looked up on PATH, even where a folder of that name exists
        # here (the repository's own `semsplat/`).
        bare = name == "semsplat" and os.sep not in value
        if os.path.exists(value) and not bare:
            setattr(args, name, os.path.abspath(value))
    # On a local cluster every task sees the driver's files: name what is missing now, not
    # once per shard and retry.
    if args.address is None:
        for name in ("scene", "cameras", "labels"):
            if not os.path.exists(getattr(args, name)):
                p.error(f"--{name} {getattr(args, name)} does not exist")
        if shutil.which(args.semsplat) is None:
            p.error(f"--semsplat {args.semsplat}: no such program (give the CLI's path)")
    return args


def fault_plan():
    """(shard, times, mode) of the injected fault, or None."""
    shard = os.environ.get("SEMSPLAT_RAY_FAULT_SHARD")
    if shard is None:
        return None
    times = os.environ.get("SEMSPLAT_RAY_FAULT_TIMES", "1")
    times = -1 if times == "always" else int(times)
    return int(shard), times, os.environ.get("SEMSPLAT_RAY_FAULT_MODE", "exit")


def injected_fault(shard, plan, marker_dir):
    """The fault mode if this attempt of `shard` is to fail. Attempts are counted by
    marker files (created exclusively), which works where the tasks share a file system,
    as on the local test cluster."""
    if plan is None or plan[0] != shard:
        return None
    _, times, mode = plan
    for attempt in range(10_000):
        marker = Path(marker_dir) / f".fault-shard{shard}-attempt{attempt}"
        try:
            fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            continue
        os.close(fd)
        return mode if times < 0 or attempt < times else None
    return None


def fuse_shard(shard, spec):
    """Runs one shard's fuse; returns (part bytes, manifest bytes), or None with
    --shared-parts. Raises if the CLI fails, so Ray retries the task."""
    n = spec["shards"]
    workdir = Path(spec["parts"]) if spec["shared"] else Path(spec["scratch"]) / f"s{shard}"
    workdir.mkdir(parents=True, exist_ok=True)
    part = workdir / f"part{shard}.npy"
    shard_arg = f"{shard}/{n}"
    fault = injected_fault(shard, spec["fault"], spec["parts"])
    if fault == "kill":
        os._exit(1)  # the worker dies mid-task, like a lost node
    if fault == "exit":
        shard_arg = "not-a-shard"
    cmd = [
        spec["semsplat"], "fuse", "--scene", spec["scene"], "--cameras", spec["cameras"],
        "--labels", spec["labels"], *spec["fuse_args"], "--shard", shard_arg,
        "--out", str(part),
    ]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(
            f"shard {shard}/{n}: semsplat exited with {run.returncode}: {run.stderr.strip()}"
        )
    if spec["shared"]:
        return None
    manifest = part.with_suffix(".manifest.json")
    result = (part.read_bytes(), manifest.read_bytes())
    part.unlink()
    manifest.unlink()
    return result


def gather(refs, args):
    """Waits for every shard; writes returned parts into --parts. Returns the failures."""
    parts = Path(args.parts)
    failures = []
    for shard, ref in enumerate(refs):
        try:
            result = ray.get(ref)
        except ray.exceptions.RayError as e:
            # A task's own exception is its cause; a dead worker is the error itself.
            cause = getattr(e, "cause", None) or e
            reason = (str(cause).strip().splitlines() or [type(cause).__name__])[0]
            failures.append(f"shard {shard}/{args.shards} failed after "
                            f"{args.max_retries} retries: {reason}")
            continue
        if result is not None:
            (parts / f"part{shard}.npy").write_bytes(result[0])
            (parts / f"part{shard}.manifest.json").write_bytes(result[1])
    return failures


def main(argv):
    args = parse_args(argv)
    if ray is None:
        sys.exit("error: this driver needs Ray on the driver and every node: pip install 'ray[default]'")
    parts = Path(args.parts).resolve()
    parts.mkdir(parents=True, exist_ok=True)
    # An earlier run's parts (merge would refuse a stale one); nothing else in the folder.
    for stale in parts.iterdir():
        if STALE_PART.fullmatch(stale.name) and stale.is_file():
            stale.unlink()
    for marker in parts.glob(".fault-shard*"):
        marker.unlink()
    if args.address:
        ray.init(address=args.address)
    else:
        ray.init(num_cpus=args.num_cpus, include_dashboard=False,
                 object_store_memory=200 << 20)
    start = time.time()
    gpus = ray.cluster_resources().get("GPU", 0)
    task = ray.remote(max_retries=args.max_retries, retry_exceptions=True)(fuse_shard)
    task = task.options(num_gpus=1) if gpus >= 1 else task.options(num_cpus=1)
    spec = {
        "shards": args.shards, "semsplat": args.semsplat, "scene": args.scene,
        "cameras": args.cameras, "labels": args.labels,
        "fuse_args": shlex.split(args.fuse_args), "parts": str(parts),
        "scratch": str(parts / ".scratch"), "shared": args.shared_parts,
        "fault": fault_plan(),
    }
    refs = [task.remote(k, spec) for k in range(args.shards)]
    failures = gather(refs, args)
    ray.shutdown()
    shutil.rmtree(parts / ".scratch", ignore_errors=True)
    if failures:
        for f in failures:
            print(f"error: {f}", file=sys.stderr)
        print(f"error: {len(failures)} of {args.shards} shards lost; nothing merged",
              file=sys.stderr)
        return 2
    print(f"{args.shards} shards fused in {time.time() - start:.1f} s "
          f"({'1 GPU each' if gpus >= 1 else 'CPU workers'})", file=sys.stderr)
    merge = [args.semsplat, "merge",
             *[str(parts / f"part{k}.npy") for k in range(args.shards)],
             "--scene", args.scene, "--out", args.out, *shlex.split(args.merge_args)]
    return subprocess.run(merge).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
