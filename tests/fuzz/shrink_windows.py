#!/usr/bin/env python3
"""Shrinks the data window of EXR fuzz inputs to at most 64 columns, renaming each to its SHA-1.

tests/fuzz/shrink_windows.py [--min-pixels N] FILE...

Long runs keep mutations of the 4 x 3 seeds whose data window libFuzzer widened (65,540 x 3 is
common): a window under the pixel limit is accepted, and each such input then costs about 1.3 s
under ASan (allocations and their page faults, instrumented loops over 200,000 pixels), against
about 10 ms for the same input 64 columns wide. The whole corpus is run on every start of the
target, so 38 of them made the `ingest` target spend CI's whole 60 s on its start (docs/fuzzing.md,
"Keeping the corpus cheap"). Shrinking keeps every other mutation of the input, and the edges it
covers: compare `-runs=0 -print_coverage=1` before and after.

Only windows of more than --min-pixels pixels (default 65,536) are shrunk; a window over the
fuzz limit (fuzz_support.h: 2^20 pixels) is refused before anything is allocated, costs nothing and
is left as it is, since it covers that refusal.
"""
import argparse
import hashlib
import os
import struct

TAG = b"dataWindow\0box2i\0"
LIMIT = 1 << 20  # fuzzLimits().maxPixels


def shrink(data: bytearray, min_pixels: int) -> bool:
    changed = False
    i = data.find(TAG)
    while i >= 0:
        j = i + len(TAG)
        if j + 20 <= len(data):
            _, x0, y0, x1, y1 = struct.unpack_from("<iiiii", data, j)
            w, h = x1 - x0 + 1, y1 - y0 + 1
            if h > 0 and min_pixels < w * h <= LIMIT:
                # xMax is the box's third int; 64 columns keep the image wider than the harness's
                # 40 x 40 corner, as most of these were.
                struct.pack_into("<i", data, j + 12, x0 + max(1, min(64, min_pixels // h)) - 1)
                changed = True
        i = data.find(TAG, j)
    return changed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-pixels", type=int, default=65536)
    parser.add_argument("files", nargs="+")
    args = parser.parse_args()
    for path in args.files:
        with open(path, "rb") as f:
            data = bytearray(f.read())
        if not shrink(data, args.min_pixels):
            continue
        new_path = os.path.join(os.path.dirname(path), hashlib.sha1(data).hexdigest())
        with open(new_path + ".tmp", "wb") as f:
            f.write(data)
        os.replace(new_path + ".tmp", new_path)
        if new_path != path:
            os.remove(path)
        print(f"{path} -> {os.path.basename(new_path)}")


if __name__ == "__main__":
    main()
