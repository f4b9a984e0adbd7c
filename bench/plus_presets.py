#!/usr/bin/env python3
"""Per-recording figures of the segmentation presets on PLUS recordings, for docs/segmentation.md.

For every recording below (bundled in data/plus/ or read from a PlusToolkit/PlusLibData git
directory) and each preset listed with it, runs
  sonoshape segment REC --calibration XML [--preset NAME] --every K -o WORK/out.slices.json
and prints one Markdown row: frames segmented, slices, the sector's unknown share (segment's
summary), the share of the sector given to a material (from the slices' polygons: 100 % minus
this is outside or unknown), material regions per slice (min / median / max) and whether the
"one label fills nearly all of most sectors" warning fired (and for which label).

  bench/plus_presets.py [--mirror DIR] [--binary build/apps/sonoshape] [--every K] [--only TEXT]

DIR: a git directory of PlusToolkit/PlusLibData (default: SONOSHAPE_PLUSLIBDATA, else
/work/.mirror/PlusToolkit+PlusLibData/repo); recordings it lacks are left out, said so.
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
DEFAULT_MIRROR = "/work/.mirror/PlusToolkit+PlusLibData/repo"
NWIRE_XML = "data/plus/PlusDeviceSet_Server_Sim_NwirePhantom.xml"
SPINE_XML = "data/plus/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml"
# (recording: data/... bundled or TestImages/... in the mirror, calibration, presets to run)
RUNS = [
    ("data/plus/NwirePhantomFreehand.igs.mha", NWIRE_XML, ["", "wires"]),
    ("data/plus/NwirePhantomFreehandCropped.igs.mha", NWIRE_XML, ["", "wires"]),
    ("data/plus/fCal_Test_Calibration_3NWires.igs.mha", NWIRE_XML, ["", "wires"]),
    ("TestImages/fCal_Test_Validation_3NWires.igs.mha", NWIRE_XML, ["", "wires"]),
    ("TestImages/WaterTankBottomTranslationCombined.igs.mha", NWIRE_XML, ["", "water-tank"]),
    ("TestImages/outputPlusTransverseProcessEnhancerTest.igs.mha", SPINE_XML, ["", "bone"]),
    ("TestImages/BoneUltrasound_L14.igs.mha", "ConfigFiles/Testing/BoneUltrasound_L14_config.xml",
     ["", "bone"]),
    ("data/plus/SpinePhantomFreehand.igs.mha", SPINE_XML, ["", "bone"]),
    ("data/plus/SegmentationTest_VLCUS_RandomStepperMotionData2_6frames.igs.mha", NWIRE_XML,
     ["", "wires"]),
]


def ring_area(ring):
    return 0.5 * abs(sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(ring, ring[1:] + ring[:1])))


def fetch(path, mirror, work):
    if path.startswith("data/"):
        return HERE / path
    blob = subprocess.run(["git", "-C", mirror, "show", "HEAD:" + path], capture_output=True)
    if blob.returncode != 0:
        return None
    out = work / Path(path).name
    out.write_bytes(blob.stdout)
    return out


def frame_count(path):
    head = path.read_bytes()[:65536].decode("latin-1", "replace")
    m = re.search(r"DimSize\s*=\s*\d+\s+\d+\s+(\d+)", head)
    return int(m.group(1)) if m else 1


def run(binary, recording, calibration, preset, every, work):
    out = work / "out.slices.json"
    cmd = [binary, "segment", str(recording), "--calibration", str(calibration), "--every",
           str(every), "-o", str(out)] + (["--preset", preset] if preset else [])
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    log = done.stdout + done.stderr
    if done.returncode != 0:
        return None, log.strip().splitlines()[-1]
    doc = json.loads(out.read_text())
    shares, regions = [], []
    for s in doc["slices"]:
        fov = ring_area(s["fov"]) if s.get("fov") else None
        material = [r for r in s["regions"] if r["label"] != "unknown"]
        area = sum(ring_area(r["polygon"]) - sum(ring_area(h) for h in r.get("holes", []))
                   for r in material)
        if fov:
            shares.append(area / fov)
        regions.append(len(material))
    unknown = re.search(r"(\d+)% of the sector unknown", log)
    warned = re.search(r"segment: (label \d+ \([^)]*\)|unknown \(no signal)[^\n]*fills at least "
                       r"95% of the sector in (\d+) of (\d+)", log)
    return {
        "slices": len(doc["slices"]),
        "unknown": int(unknown.group(1)) if unknown else None,
        "material_mean": 100 * statistics.mean(shares) if shares else 0.0,
        "material_max": 100 * max(shares) if shares else 0.0,
        "regions": (min(regions), statistics.median(regions), max(regions)) if regions else None,
        "warning": f"{warned.group(1).replace(' (no signal', '')} in {warned.group(2)}/"
                   f"{warned.group(3)}" if warned else "none",
    }, log


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mirror", default=os.environ.get("SONOSHAPE_PLUSLIBDATA", DEFAULT_MIRROR))
    parser.add_argument("--binary", default=str(HERE / "build" / "apps" / "sonoshape"))
    parser.add_argument("--only", default="", help="only recordings whose name contains this")
    parser.add_argument("--every", type=int, default=0,
                        help="segment every K-th frame (default: about 24 frames per recording)")
    args = parser.parse_args()
    print("| recording | preset | frames | slices | unknown | material share mean / max | "
          "material regions per slice min / median / max | warning |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for recording, calibration, presets in RUNS:
            if args.only not in recording:
                continue
            local = fetch(recording, args.mirror, work)
            cal = fetch(calibration, args.mirror, work)
            name = Path(recording).name
            if local is None or cal is None:
                print(f"| `{name}` | | | | | | | not in the mirror |", flush=True)
                continue
            frames = frame_count(local)
            every = args.every or max(1, frames // 24)
            for preset in presets:
                got, log = run(args.binary, local, cal, preset, every, work)
                label = f"`{preset}`" if preset else "defaults"
                if got is None:
                    print(f"| `{name}` | {label} | | | | | | refused: {log} |", flush=True)
                    continue
                r = got["regions"]
                print(f"| `{name}` | {label} | {(frames + every - 1) // every} of {frames} | "
                      f"{got['slices']} | {got['unknown']} % | {got['material_mean']:.1f} / "
                      f"{got['material_max']:.1f} % | {r[0]} / {r[1]:g} / {r[2]} | "
                      f"{got['warning']} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
