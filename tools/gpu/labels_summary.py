#!/usr/bin/env python3
"""Issue 16's time goal from a device run: tools/gpu/device_run.sh's `labels` cases, read
back here (its ours.jsonl and bench.log), as the tables docs/gpu.md quotes.

  python3 tools/gpu/labels_summary.py OUT/ours.jsonl [OUT/bench.log]

Per `bench fuse` case with label maps and per build ("after" this build, "before" the
build packed with BEFORE_BIN): each method's wall seconds, its ratio to FlashSplat's in
the same run (the goal: about 1.5x), and the consensus's split (label waits, the label
regions' GPU time, the clustering and the decision, the host threads). Per `semsplat
fuse` process case: its wall seconds and ratio. From bench.log's `host scaling office
labels` lines: per core set the fastest clustering and decision of its repetitions, the
outputs' hashes, and the model printed on one core.
"""
import json
import re
import sys
from collections import defaultdict


def load_cases(path):
    cases = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line:
                cases.append(json.loads(line))
    return cases


def ratio(x, base):
    return f"{x / base:.2f}x" if x and base else "-"


def fmt(x, form):
    return form.format(x) if x is not None else "-"


def bench_rows(case):
    """One row per method of a `bench fuse` case: its figures and ratio to FlashSplat."""
    methods = case.get("methods") or []
    flashsplat = next((m["wall_s"] for m in methods if m.get("key") == "flashsplat"), None)
    rows = []
    for m in methods:
        observe = m.get("observe") or {}
        rows.append([
            m.get("key", m.get("method", "?")),
            f"{m['wall_s']:.3f}",
            ratio(m["wall_s"], flashsplat),
            f"{m.get('label_wait_s', 0):.3f}",
            fmt(observe.get("regions_gpu_ms"), "{:.1f}"),
            f"{m.get('segments_s', 0):.3f}",
            f"{m.get('decide_s', 0):.3f}",
            str(case.get("host_threads", "-")),
        ])
    return rows


def table(header, rows):
    widths = [max(len(str(r[i])) for r in [header] + rows) for i in range(len(header))]
    line = lambda r: "| " + " | ".join(str(c).ljust(w) for c, w in zip(r, widths)) + " |"
    out = [line(header), "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    return "\n".join(out + [line(r) for r in rows])


def fuse_tables(cases):
    out = []
    header = ["method", "wall s", "vs FlashSplat", "label wait s", "regions GPU ms",
              "clustering s", "decision s", "host threads"]
    for case in cases:
        name = case.get("case", "")
        if "labels" not in name or "methods" not in case:
            continue
        build = case.get("build", "")
        out.append(f"### {name}{' (' + build + ')' if build else ''}\n")
        out.append(table(header, bench_rows(case)) + "\n")
    processes = defaultdict(dict)
    for case in cases:
        name = case.get("case", "")
        if name.startswith("fuse cli") and "process_wall_s" in case:
            scene, method = name.rsplit(" ", 1)
            processes[(scene, case.get("build", ""))][method] = case["process_wall_s"]
    for (scene, build), walls in processes.items():
        base = walls.get("flashsplat")
        rows = [[m, f"{w:.3f}", ratio(w, base)] for m, w in walls.items()]
        out.append(f"### {scene}, whole processes{' (' + build + ')' if build else ''}\n")
        out.append(table(["method", "process wall s", "vs FlashSplat"], rows) + "\n")
    return out


# "host scaling" lines are the order's clustering, "host scaling rounds" --clustering rounds.
SCALING = re.compile(
    r"^host scaling( rounds)?, cores (\S+): clustering ([0-9.]+) s, decision ([0-9.]+) s, outputs (\w+)")
MODEL = re.compile(
    r"^host scaling( rounds)?, cores (\S+):\s+(clustering|decision) modeled \(threads: s\) (.*?);")
# After each repetition's line (builds from 2026-12-01 on): the allocations its passes made
# on the worker threads, which wait on each other under the CLI's one malloc arena, and
# the process's page faults.
ALLOCATIONS = re.compile(
    r"^host scaling( rounds)?, cores (\S+):\s+allocations on the worker threads: "
    r"clustering (\d+), decision (\d+)(?:; page faults: clustering (\d+), decision (\d+))?")


def scaling_tables(log_path):
    runs, models, allocations = defaultdict(list), {}, defaultdict(list)
    with open(log_path, errors="replace") as f:
        for line in f:
            m = SCALING.match(line)
            if m:
                clustering = "rounds" if m.group(1) else "order"
                runs[(clustering, m.group(2))].append(
                    (float(m.group(3)), float(m.group(4)), m.group(5)))
                continue
            m = MODEL.match(line)
            if m:
                models[("rounds" if m.group(1) else "order", m.group(3))] = m.group(4)
                continue
            m = ALLOCATIONS.match(line)
            if m:
                faults = f"; faults {m.group(5)} / {m.group(6)}" if m.group(5) else ""
                allocations[("rounds" if m.group(1) else "order", m.group(2))].append(
                    f"{m.group(3)} / {m.group(4)}{faults}")
    if not runs:
        return []
    rows = [[clustering, cores, f"{min(r[0] for r in reps):.3f}",
             f"{min(r[1] for r in reps):.3f}", str(len(reps)), " ".join(sorted({r[2] for r in reps})),
             ", ".join(allocations.get((clustering, cores), [])) or "-"]
            for (clustering, cores), reps in runs.items()]
    out = ["### host scaling office labels (consensus_host, fastest of the repetitions)\n",
           table(["clustering", "cores", "clustering s", "decision s", "repetitions", "outputs",
                  "worker allocations (clustering / decision); page faults"], rows) + "\n"]
    for (clustering, step), figures in models.items():
        out.append(f"{step} ({clustering}) modeled from one core's items, its last repetition "
                   f"(threads: s): {figures}\n")
    return out


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    out = fuse_tables(load_cases(sys.argv[1]))
    if len(sys.argv) == 3:
        out += scaling_tables(sys.argv[2])
    print("\n".join(out) if out else "no labels cases in these files")


if __name__ == "__main__":
    main()
