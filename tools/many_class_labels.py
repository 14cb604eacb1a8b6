#!/usr/bin/env python3
"""Label maps of thousands of classes, for measuring a fusion's memory and time as the
class count grows (open-vocabulary segmenters, mask ids).

Reads a folder of 8-bit grayscale PNG maps (a `semsplat synth` room's `instances/` or
`labels/`) and writes 16-bit maps in which each (view, id, block of BLOCK x BLOCK pixels)
takes a random class id below CLASSES; 255 stays unlabeled (65535). Plain Python (zlib,
struct): no imaging library needed.

    python3 tools/many_class_labels.py ROOM/instances OUT_DIR --classes 60000 --block 40 --seed 1
"""
import argparse
import os
import random
import struct
import zlib


def read_gray8(path):
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise SystemExit(f"{path}: not a PNG")
    at, idat, width, height = 8, b"", 0, 0
    while at < len(data):
        (n,) = struct.unpack(">I", data[at : at + 4])
        kind, body = data[at + 4 : at + 8], data[at + 8 : at + 8 + n]
        at += 12 + n
        if kind == b"IHDR":
            width, height, depth, colour = struct.unpack(">IIBB", body[:10])
            if (depth, colour) != (8, 0):
                raise SystemExit(f"{path}: not 8-bit grayscale")
        elif kind == b"IDAT":
            idat += body
    raw, rows, prev = zlib.decompress(idat), [], bytearray(width)
    for y in range(height):
        start = y * (width + 1)
        kind, line = raw[start], bytearray(raw[start + 1 : start + 1 + width])
        for x in range(width):
            a, b = (line[x - 1] if x else 0), prev[x]
            c = prev[x - 1] if x else 0
            if kind == 1:
                line[x] = (line[x] + a) & 255
            elif kind == 2:
                line[x] = (line[x] + b) & 255
            elif kind == 3:
                line[x] = (line[x] + (a + b) // 2) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        prev = line
    return width, height, rows


def write_gray16(path, width, height, rows):
    raw = b"".join(b"\x00" + b"".join(struct.pack(">H", v) for v in row) for row in rows)

    def chunk(kind, body):
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
    png += chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
    open(path, "wb").write(png)


def main():
    cli = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    cli.add_argument("maps")
    cli.add_argument("out")
    cli.add_argument("--classes", type=int, default=60000, help="ids drawn below this (< 65535)")
    cli.add_argument("--block", type=int, default=40, help="pixels per block side")
    cli.add_argument("--seed", type=int, default=1)
    args = cli.parse_args()
    if not 0 < args.classes < 65535:
        raise SystemExit("--classes must be in 1..65534")
    os.makedirs(args.out, exist_ok=True)
    rng, ids = random.Random(args.seed), {}
    for name in sorted(f for f in os.listdir(args.maps) if f.endswith(".png")):
        width, height, rows = read_gray8(os.path.join(args.maps, name))
        out = []
        for y, row in enumerate(rows):
            key = lambda x, v: (name, v, x // args.block, y // args.block)
            out.append(
                [65535 if v == 255 else ids.setdefault(key(x, v), rng.randrange(args.classes))
                 for x, v in enumerate(row)]
            )
        write_gray16(os.path.join(args.out, name), width, height, out)
    print(f"{len(set(ids.values()))} classes in {args.out}")


if __name__ == "__main__":
    main()
