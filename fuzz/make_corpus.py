#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets (fuzz/corpus/<target>/) from this repository's data.

Seeds are small on purpose (a few KB): libFuzzer mutates short inputs much faster, and a seed only
needs to reach each branch of the format once. Big files are trimmed: slice sets and .csl keep
their first slices with every ring subsampled, sequences keep two frames of a small image with the
original header's fields. Run from anywhere; it overwrites the seeds it writes.
"""
import gzip
import json
import math
import pathlib
import re
import struct
import zlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
CORPUS = ROOT / "fuzz" / "corpus"


def put(target, name, data):
    folder = CORPUS / target
    folder.mkdir(parents=True, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    (folder / name).write_bytes(data)


def subsample(ring, keep):
    step = max(1, math.ceil(len(ring) / keep))
    return ring[::step]


def trim_slice_set(path, slices=3, keep=10):
    doc = json.loads(path.read_text())
    doc["slices"] = doc["slices"][:slices]
    for s in doc["slices"]:
        for region in s.get("regions", []):
            region["polygon"] = subsample(region["polygon"], keep)
            region["holes"] = [subsample(h, keep) for h in region.get("holes", [])]
            if not region["holes"]:
                del region["holes"]
        if "fov" in s:
            s["fov"] = subsample(s["fov"], keep)
    return json.dumps(doc)


def trim_csl(path, planes=3, keep=10):
    """Keeps the first planes, each component's contour subsampled to about `keep` vertices."""
    tokens = path.read_text().split()
    assert tokens[0] == "CSLC"
    n_planes, n_labels = int(tokens[1]), tokens[2]
    at = 3
    out = []
    for _ in range(min(planes, n_planes)):
        index, n_vertices, n_components = tokens[at], int(tokens[at + 1]), int(tokens[at + 2])
        plane = tokens[at + 3:at + 7]
        at += 7
        vertices = [tokens[at + 3 * i:at + 3 * i + 3] for i in range(n_vertices)]
        at += 3 * n_vertices
        components = []
        for _ in range(n_components):
            count = tokens[at]
            n = int(re.match(r"\d+", count).group())
            label = tokens[at + 1]
            indices = [int(t) for t in tokens[at + 2:at + 2 + n]]
            at += 2 + n
            components.append((count[len(str(n)):], label, subsample(indices, keep)))
        used = sorted({i for _, _, idx in components for i in idx})
        remap = {old: new for new, old in enumerate(used)}
        out.append(f"{index} {len(used)} {len(components)} {' '.join(plane)}")
        out += [" ".join(vertices[i]) for i in used]
        out += [f"{len(idx)}{hole} {label} {' '.join(str(remap[i]) for i in idx)}"
                for hole, label, idx in components]
        out.append("")
    return f"CSLC\n{len(out) and min(planes, n_planes)} {n_labels}\n\n" + "\n".join(out)


def mha_header_fields(path, frames=2):
    """The header lines of a PLUS .mha: global fields and those of the first `frames` frames."""
    raw = path.read_bytes()
    header = raw[:raw.index(b"ElementDataFile")].decode()
    lines = []
    for line in header.splitlines():
        m = re.match(r"Seq_Frame(\d+)_", line)
        if m and int(m.group(1)) >= frames:
            continue
        if line.split(" =")[0] in ("NDims", "DimSize", "CompressedData", "CompressedDataSize",
                                   "BinaryData", "BinaryDataByteOrderMSB", "ElementType"):
            continue
        lines.append(line.rstrip())
    return lines


def pixels(width, height, frames):
    return bytes((7 * x + 13 * y + 29 * f) % 256
                 for f in range(frames) for y in range(height) for x in range(width))


def mha(fields, width, height, frames, compressed):
    data = pixels(width, height, frames)
    layout = [f"NDims = 3", f"DimSize = {width} {height} {frames}", "ElementType = MET_UCHAR",
              "BinaryData = True", "BinaryDataByteOrderMSB = False"]
    if compressed:
        data = zlib.compress(data)
        layout += ["CompressedData = True", f"CompressedDataSize = {len(data)}"]
    else:
        layout += ["CompressedData = False"]
    return ("\n".join(fields[:1] + layout + fields[1:]) + "\nElementDataFile = LOCAL\n").encode() + data


def nrrd_plus_fields(path, frames=2):
    raw = path.read_bytes()
    header = raw[:raw.index(b"\n\n")].decode()
    keep = []
    for line in header.splitlines():
        m = re.match(r"Seq_Frame(\d+)_", line)
        if m and int(m.group(1)) >= frames:
            continue
        if line.startswith(("sizes:", "encoding:", "NRRD", "dimension:", "type:", "kinds:",
                            "endian:")):
            continue
        keep.append(line)
    return keep


def nrrd(fields, width, height, frames, encoding, layout="plus"):
    data = pixels(width, height, frames)
    head = ["NRRD0004", "type: uint8"]
    if layout == "plus":
        head += ["dimension: 3", f"sizes: {width} {height} {frames}", "kinds: domain domain list"]
    else:  # Slicer: W H 1 N with a 3D space and per-frame index values
        head += ["dimension: 4", f"sizes: {width} {height} 1 {frames}",
                 "kinds: domain domain domain list", "space: left-posterior-superior",
                 "space directions: (0.5,0,0) (0,0.5,0) (0,0,1) none",
                 "space origin: (-10,-5,2)", "axis 3 index type:=numeric",
                 "axis 3 index values:=" + " ".join(str(0.1 * k) for k in range(frames)),
                 "axis 3 item 0 ProbeToTrackerTransform:=1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"]
    if encoding == "gzip":
        head.append("encoding: gzip")
        body = gzip.compress(data, mtime=0)
    elif encoding == "text":
        head.append("encoding: text")
        body = " ".join(str(b) for b in data).encode()
    else:
        head.append("encoding: raw")
        body = data
    return ("\n".join(head + fields) + "\n\n").encode() + body


CUBE_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
CUBE_F = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4), (1, 2, 6), (1, 6, 5),
          (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)]


def ply_ascii():
    lines = ["ply", "format ascii 1.0", "comment cube", f"element vertex {len(CUBE_V)}",
             "property float x", "property float y", "property float z",
             f"element face {len(CUBE_F)}", "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(map(str, v)) for v in CUBE_V]
    lines += ["3 " + " ".join(map(str, f)) for f in CUBE_F]
    return "\n".join(lines) + "\n"


def ply_binary(endian):
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    head = ["ply", f"format {fmt} 1.0", f"element vertex {len(CUBE_V)}", "property double x",
            "property double y", "property double z", "property uchar red",
            f"element face {len(CUBE_F)}", "property list uchar uint vertex_indices",
            "element edge 1", "property int vertex1", "property int vertex2", "end_header"]
    body = b"".join(struct.pack(endian + "dddB", *v, 200) for v in CUBE_V)
    body += b"".join(struct.pack(endian + "BIII", 3, *f) for f in CUBE_F)
    body += struct.pack(endian + "ii", 0, 1)
    return ("\n".join(head) + "\n").encode() + body


def obj():
    lines = ["# cube", "o cube"] + [f"v {x} {y} {z}" for x, y, z in CUBE_V]
    lines += ["vn 0 0 1", "vt 0 0"]
    lines += [f"f {a + 1}/1/1 {b + 1}//1 {c + 1}" for a, b, c in CUBE_F[:6]]
    lines += [f"f {a - 8} {b - 8} {c - 8}" for a, b, c in CUBE_F[6:]]  # relative indices
    return "\n".join(lines) + "\n"


def off():
    lines = ["OFF", f"{len(CUBE_V)} 6 12"] + [" ".join(map(str, v)) for v in CUBE_V]
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    lines += ["4 " + " ".join(map(str, q)) for q in quads]
    return "\n".join(lines) + "\n"


def stl_ascii():
    out = ["solid cube"]
    for f in CUBE_F:
        out += ["  facet normal 0 0 0", "    outer loop"]
        out += ["      vertex " + " ".join(map(str, CUBE_V[i])) for i in f]
        out += ["    endloop", "  endfacet"]
    return "\n".join(out + ["endsolid cube"]) + "\n"


def stl_binary():
    body = b"".join(struct.pack("<12fH", 0, 0, 0, *CUBE_V[f[0]], *CUBE_V[f[1]], *CUBE_V[f[2]], 0)
                    for f in CUBE_F)
    return b"binary cube".ljust(80, b"\0") + struct.pack("<I", len(CUBE_F)) + body


def frames(*parts):
    """The mesh_stream target's input: each frame as a 4-byte little-endian length and its bytes."""
    out = b""
    for p in parts:
        p = p.encode() if isinstance(p, str) else p
        out += struct.pack("<I", len(p)) + p
    return out


def stream_seeds():
    scan = "0d9c5a8e-4c1f-4a52-9d1e-3b1f2a6c7e90"
    pos = [c for v in CUBE_V for c in v]
    header = {"v": 1, "seq": 3, "scan": scan, "label": 1, "name": "liver", "units": "mm",
              "frame": "reference", "timestamp_s": 1.5, "slices": 4, "vertex_count": 8,
              "triangle_count": 12, "bounds": {"min": [0, 0, 0], "max": [1, 1, 1]}}
    yield "mesh", frames("mesh.1", json.dumps(header), struct.pack("<24f", *pos),
                         struct.pack("<36I", *[i for f in CUBE_F for i in f]))
    normals = dict(header, normals=True, seq=4)
    yield "mesh_normals", frames("mesh.1", json.dumps(normals), struct.pack("<24f", *pos),
                                 struct.pack("<36I", *[i for f in CUBE_F for i in f]),
                                 struct.pack("<24f", *([0, 0, 1] * 8)))
    empty = dict(header, label=2, vertex_count=0, triangle_count=0, bounds=None, seq=5)
    yield "mesh_empty", frames("mesh.2", json.dumps(empty), b"", b"")
    slice_header = {"v": 1, "seq": 1, "scan": scan, "index": 0,
                    "plane": {"origin": [0, 0, 0.5], "u": [1, 0, 0], "v": [0, 1, 0]},
                    "timestamp": 0.1, "fov": [[-5, 0], [5, 0], [5, 8], [-5, 8]],
                    "regions": [{"label": 1, "polygon": [[0, 1], [2, 1], [2, 3], [0, 3]],
                                 "holes": [[[0.5, 1.5], [0.5, 2.5], [1.5, 2.5], [1.5, 1.5]]]},
                                {"label": "unknown", "polygon": [[3, 4], [4, 4], [3.5, 5]]}]}
    yield "slice", frames("slice", json.dumps(slice_header))
    status = {"v": 1, "seq": 6, "scan": scan, "frames_received": 10, "frames_dropped": 1,
              "slices": 4, "arrangement_ms": 1.0, "field_ms": 2.0, "smoothing_ms": 3.0,
              "mesh_ms": 4.0, "total_ms": 10.0, "update_ms": 11.0, "latency_ms": 12.0,
              "state": "scanning"}
    yield "status", frames("status", json.dumps(status))
    yield "status_error", frames("status", json.dumps(dict(status, state="error",
                                                           message="tracker lost")))
    frame = {"v": 1, "seq": 2, "scan": scan, "index": 0, "timestamp_s": 0.1, "format": "gray8",
             "width": 4, "height": 3, "plane": {"origin": [0, 0, 0], "u": [1, 0, 0],
                                                "v": [0, 1, 0]}, "size_mm": [8, 6]}
    yield "frame", frames("frame", json.dumps(frame), bytes(range(12)))
    yield "end", frames("end", json.dumps({"seq": 6}))


def igtl_header(type_name, body, device="Probe"):
    """A 58-byte OpenIGTLink v1 header for `body` (CRC-64 ECMA-182, as igtl_util's crc64)."""
    crc = 0
    for byte in body:
        crc ^= byte << 56
        for _ in range(8):
            crc = ((crc << 1) ^ 0x42F0E1EBA9EA3693) if crc & (1 << 63) else crc << 1
            crc &= (1 << 64) - 1
    return (struct.pack(">H", 1) + type_name.encode().ljust(12, b"\0") +
            device.encode().ljust(20, b"\0") + struct.pack(">QQQ", 0, len(body), crc))


def igtl_seeds():
    """Bodies for igtl_messages (byte 0: 0 IMAGE, 1 TRANSFORM, 2 TDATA; the target makes the
    header) and client byte streams for igtl_server_requests (byte 0: the piece size)."""
    matrix = struct.pack(">12f", 0.2, 0, 0, 0, 0.2, 0, 0, 0, 1, 0, 0, 0)
    image = (struct.pack(">HBBBB3H", 1, 1, 3, 2, 1, 4, 3, 1) + matrix +
             struct.pack(">3H3H", 0, 0, 0, 4, 3, 1) + bytes(range(12)))
    transform = struct.pack(">12f", 1, 0, 0, 0, 1, 0, 0, 0, 1, 10, 20, 30)
    element = b"Probe".ljust(20, b"\0") + struct.pack(">BB", 1, 0) + transform
    yield "igtl_messages", "image_4x3_uint8", b"\x00" + image
    yield "igtl_messages", "transform", b"\x01" + transform
    yield "igtl_messages", "tdata_probe_and_stylus", (
        b"\x02" + element + b"Stylus".ljust(20, b"\0") + struct.pack(">BB", 1, 0) + transform)
    yield "igtl_messages", "image_raw_header", b"\x80" + igtl_header("IMAGE", image) + image
    status = struct.pack(">HQ", 1, 0) + b"OK".ljust(20, b"\0") + b"fine\0"
    requests = [igtl_header("GET_STATUS", b"", "Scan"), igtl_header("GET_POLYDATA", b"", "organ"),
                igtl_header("GET_IMAGE", b"", "Image"), igtl_header("STATUS", status) + status]
    yield "igtl_server_requests", "get_every_kind", b"\x3a" + b"".join(requests)
    yield "igtl_server_requests", "split_in_threes", b"\x02" + b"".join(requests)
    yield "igtl_server_requests", "announces_2_mib", b"\x3a" + igtl_header(
        "IMAGE", b"")[:42] + struct.pack(">QQ", 2 << 20, 0)


def journal_seeds():
    """scan_journal: record payloads separated by 0xFF (the target adds lengths and CRCs)."""
    args = json.dumps({"type": "scan", "version": 1, "arguments": ["--source", "sim:default"],
                       "working_directory": "/tmp"})
    corners = [[0, 0, 0], [40, 0, 0], [40, 0, 30], [0, 0, 30]]
    slice_ = {"origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 0, 1],
              "regions": [{"label": 1, "polygon": [[10, 10], [20, 10], [15, 20]]}]}
    keyframe = json.dumps({"type": "keyframe", "frame": 3,
                           "plane": {"corners_mm": corners, "normal": [0, 1, 0]},
                           "slice": slice_})
    yield "scan_journal", "scan_keyframe_end", "\xff".join(
        [args, keyframe, json.dumps({"type": "resume", "after_frame": 3}), keyframe,
         json.dumps({"type": "end"})]).encode("latin-1")
    yield "scan_journal", "torn_last_record", ("\xff".join([args, keyframe]) + "\xff\xfe" +
                                                keyframe).encode("latin-1")


def view_server_seeds():
    """view_server_requests: byte 0 bit 0 clear: raw HTTP; set: WebSocket frames after the
    target's upgrade (bits 1-7: the piece size of the sends)."""
    host = "Host: 127.0.0.1:8080\r\n"
    yield "page", b"\xfe" + f"GET / HTTP/1.1\r\n{host}\r\n".encode()
    yield "script_pipelined", b"\x10" + (f"GET /src/main.js HTTP/1.1\r\n{host}\r\n" * 2).encode()
    yield "dot_dot", b"\xfe" + f"GET /../../etc/passwd HTTP/1.1\r\n{host}\r\n".encode()
    yield "rebound_host", b"\xfe" + b"GET / HTTP/1.1\r\nHost: attacker.example:8080\r\n\r\n"
    yield "head_and_post", b"\xfe" + (f"HEAD / HTTP/1.1\r\n{host}\r\n"
                                       f"POST / HTTP/1.1\r\n{host}Content-Length: 3\r\n\r\nabc").encode()
    mask = b"\x01\x02\x03\x04"
    text = bytes(c ^ mask[i % 4] for i, c in enumerate(b"hello"))
    yield "ws_masked_text_then_close", b"\x01" + b"\x81\x85" + mask + text + b"\x88\x80" + mask
    yield "ws_announces_16_mib", b"\x01" + b"\x82\xff" + struct.pack(">Q", 16 << 20) + mask



def main():
    real = ROOT / "tests" / "data" / "real_input"
    hostile = ROOT / "tests" / "data" / "hostile"
    examples = ROOT / "data" / "examples"
    plus = ROOT / "data" / "plus"

    put("slices_json", "figure_eight.slices.json", trim_slice_set(real / "figure_eight.slices.json"))
    for name in ("two_cylinders_unknown", "two_cylinders_noise", "two_labels"):
        put("slices_json", f"{name}.slices.json", trim_slice_set(examples / f"{name}.slices.json"))
    for f in sorted(hostile.glob("*.slices.json")):
        if f.stat().st_size <= 4096:
            put("slices_json", f.name, json.dumps(json.loads(f.read_text())))

    for f in sorted(real.glob("*.csl")):
        put("csl", f.name, trim_csl(f))
    for f in sorted(hostile.glob("*.csl")):
        put("csl", f.name, f.read_bytes())

    fields = mha_header_fields(plus / "NwirePhantomFreehand.igs.mha")
    put("sequence_mha", "nwire_2_frames_zlib.igs.mha", mha(fields, 16, 12, 2, True))
    put("sequence_mha", "nwire_2_frames_raw.igs.mha", mha(fields, 16, 12, 2, False))
    put("sequence_mha", "one_frame.mha",
        b"ObjectType = Image\nNDims = 2\nDimSize = 4 3\nElementType = MET_UCHAR\n"
        b"ElementDataFile = LOCAL\n" + pixels(4, 3, 1))
    put("sequence_mha", "dimsize_512x512x1e6.mha", (hostile / "dimsize_512x512x1e6.mha").read_bytes())

    nfields = nrrd_plus_fields(plus / "NwirePhantomFreehand.igs.nrrd")
    put("sequence_nrrd", "nwire_2_frames_gzip.igs.nrrd", nrrd(nfields, 16, 12, 2, "gzip"))
    put("sequence_nrrd", "nwire_2_frames_raw.igs.nrrd", nrrd(nfields, 16, 12, 2, "raw"))
    put("sequence_nrrd", "text_2_frames.igs.nrrd", nrrd([], 4, 3, 2, "text"))
    put("sequence_nrrd", "slicer_3_frames.seq.nrrd", nrrd([], 4, 3, 3, "raw", layout="slicer"))
    for f in sorted(hostile.glob("*.nrrd")):
        put("sequence_nrrd", f.name, f.read_bytes())

    for f in sorted(plus.glob("*.xml")):
        put("plus_config", f.name, f.read_bytes())

    doc = ROOT / "docs" / "segmentation.md"
    example = doc.read_text().split("## Config")[1].split("```json")[1].split("```")[0]
    put("segmentation_config", "docs_example.json", example)
    variant = json.loads(example)
    variant.update(method="graph_cut", sector=[[0, 0], [255, 0], [200, 255], [50, 255]],
                   shadow_grey=20)
    variant["labels"][0].update(thickness_mm=4.5, seed_mm=[1.5, -2, 30])
    put("segmentation_config", "graph_cut_polygon.json", json.dumps(variant))
    put("segmentation_config", "minimal.json", json.dumps({
        "format": "sonoshape-segmentation", "version": 1,
        "labels": [{"id": 1, "grey_mean": 150, "grey_std": 40}], "sector": "auto"}))

    put("mesh", "cube_ascii.ply", b"0" + ply_ascii().encode())
    put("mesh", "cube_le.ply", b"0" + ply_binary("<"))
    put("mesh", "cube_be.ply", b"0" + ply_binary(">"))
    put("mesh", "cube.obj", b"1" + obj().encode())
    put("mesh", "cube.off", b"2" + off().encode())
    put("mesh", "cube_ascii.stl", b"3" + stl_ascii().encode())
    put("mesh", "cube_binary.stl", b"3" + stl_binary())
    for f in sorted(hostile.iterdir()):
        prefix = {".ply": b"0", ".obj": b"1", ".off": b"2", ".stl": b"3"}.get(f.suffix)
        if prefix:
            put("mesh", f.name, prefix + f.read_bytes())

    for name, data in stream_seeds():
        put("mesh_stream", name + ".frames", data)
    for target, name, data in [*igtl_seeds(), *journal_seeds()]:
        put(target, name, data)
    for name, data in view_server_seeds():
        put("view_server_requests", name, data)


if __name__ == "__main__":
    main()
