#!/usr/bin/env python3
"""Cuts small test pieces out of PlusLibData recordings (data/plus/README.md lists each one).

  trim_plus.py frames IN.igs.mha OUT.igs.mha FIRST COUNT
      keeps frames FIRST..FIRST+COUNT-1 of a PLUS MetaImage sequence (zlib or raw pixels), with
      their per-frame fields renumbered from 0; every global field is kept as it is.
  trim_plus.py mhd IN.igs.mha OUT.igs.mhd FIRST COUNT
      the same, written as a .mhd header with its pixels uncompressed in OUT.raw beside it.
  trim_plus.py results IN.results.xml OUT.results.xml
      keeps a PLUS calibration result up to the end of its <CalibrationResults>, without the
      error report and its per-frame validation data (which make the file a megabyte).
"""
import re
import sys
import zlib
from pathlib import Path


def read_mha(path):
    data = Path(path).read_bytes()
    end = data.index(b"ElementDataFile")
    end = data.index(b"\n", end) + 1
    header = data[:end].decode("latin-1").splitlines()
    fields, frames = [], {}
    for line in header:
        if "=" not in line:
            continue
        key, value = (s.strip() for s in line.split("=", 1))
        m = re.match(r"Seq_Frame(\d+)_(.*)", key)
        if m:
            frames.setdefault(int(m.group(1)), []).append((m.group(2), value))
        else:
            fields.append((key, value))
    f = dict(fields)
    w, h, n = (int(x) for x in f["DimSize"].split())
    pixels = data[end:]
    if f.get("CompressedData", "False").lower() == "true":
        pixels = zlib.decompress(pixels[: int(f["CompressedDataSize"])])
    assert len(pixels) == w * h * n, "unexpected pixel count"
    return fields, frames, (w, h, n), pixels


def write(fields, frames, size, pixels, out, first, count, data_file=None):
    w, h, _ = size
    lines = []
    compressed = None if data_file else zlib.compress(pixels, 9)
    for key, value in fields:
        if key == "ElementDataFile":
            continue
        if key == "DimSize":
            value = f"{w} {h} {count}"
        elif key == "CompressedData":
            value = "False" if data_file else "True"
        elif key == "CompressedDataSize":
            if data_file:
                continue
            value = str(len(compressed))
        lines.append(f"{key} = {value}")
    for k in range(count):
        for name, value in frames.get(first + k, []):
            lines.append(f"Seq_Frame{k:04d}_{name} = {value}")
    lines.append(f"ElementDataFile = {data_file or 'LOCAL'}")
    header = ("\n".join(lines) + "\n").encode("latin-1")
    Path(out).write_bytes(header + (b"" if data_file else compressed))
    if data_file:
        (Path(out).parent / data_file).write_bytes(pixels)


def trim(path, out, first, count, as_mhd):
    fields, frames, size, pixels = read_mha(path)
    w, h, n = size
    assert 0 <= first and first + count <= n, "frames out of range"
    piece = pixels[first * w * h : (first + count) * w * h]
    data_file = Path(out).with_suffix("").with_suffix("").name + ".raw" if as_mhd else None
    write(fields, frames, size, piece, out, first, count, data_file)


def trim_results(path, out):
    # Text, not a parsed tree: the calibration's lines stay byte for byte as PLUS wrote them.
    text = Path(path).read_text(encoding="latin-1")
    end = text.index("</CalibrationResults>") + len("</CalibrationResults>")
    root = re.match(r"\s*<(\w+)", text).group(1)
    Path(out).write_text(text[:end] + f"\n</{root}>\n", encoding="latin-1")


if __name__ == "__main__":
    mode = sys.argv[1]
    if mode in ("frames", "mhd"):
        trim(sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), mode == "mhd")
    elif mode == "results":
        trim_results(sys.argv[2], sys.argv[3])
    else:
        sys.exit(__doc__)
