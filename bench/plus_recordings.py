#!/usr/bin/env python3
"""Segments and replays the real tracked ultrasound recordings of PLUS's test data.

The recordings are the `TestImages/` of PlusToolkit/PlusLibData (BSD-3); the bundled `data/plus/`
holds those the tests need, and this script reads the rest (BoneUltrasound_L14, 3.7 MB) from a
checkout you pass. For each recording and its calibration it runs
  sonoshape segment REC --calibration XML -o WORK/NAME.slices.json
  sonoshape scan --source replay:REC --calibration XML --fast --keyframe-angle-deg 0
                 --keyframe-distance-mm 0 --out WORK/NAME.scan      (every frame offered)
and prints one Markdown table: frames, frames that gave a slice through `segment` and through
`scan`, frames that failed, repairs, and whether the `.mha` and `.nrrd` copies of the N-wire
recording give byte-identical slice sets. `--write-doc` puts the table into docs/benchmarks.md
between `<!-- plus_recordings:begin -->` and `<!-- plus_recordings:end -->`. The exit status is
non-zero when a recording gives slices on fewer than 95 % of its frames.

Usage: bench/plus_recordings.py PLUSLIBDATA [--binary build/apps/sonoshape]
                                [--work out/bench/plus_recordings] [--write-doc]
"""
import argparse
import filecmp
import json
import os
import re
import subprocess
import sys
import time

from doc_tables import provenance, write_between_markers

SPINE = "data/plus/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml"
NWIRE = "data/plus/PlusDeviceSet_Server_Sim_NwirePhantom.xml"
# (name, recording, calibration): "data/..." paths are bundled, the others are in PLUSLIBDATA.
RECORDINGS = [
    ("fCal_Test_Calibration_3NWires", "data/plus/fCal_Test_Calibration_3NWires.igs.mha", NWIRE),
    ("BoneUltrasound_L14", "TestImages/BoneUltrasound_L14.igs.mha",
     "ConfigFiles/Testing/BoneUltrasound_L14_config.xml"),
    ("SpinePhantomFreehand", "data/plus/SpinePhantomFreehand.igs.mha", SPINE),
    ("NwirePhantomFreehand (.mha)", "data/plus/NwirePhantomFreehand.igs.mha", SPINE),
    ("NwirePhantomFreehand (.nrrd)", "data/plus/NwirePhantomFreehand.igs.nrrd", SPINE),
]
SUMMARY = re.compile(r"(\d+) slices from (\d+) frames .* (\d+) failed, (\d+) repairs")


def locate(root, plus_dir, path):
    return os.path.join(root, path) if path.startswith("data/") else os.path.join(plus_dir, path)


def run(cmd):
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(" ".join(cmd) + "\n" + result.stderr)
        raise SystemExit(1)
    return result


def one_recording(args, root, name, recording, calibration):
    stem = re.sub(r"\W+", "_", name).strip("_")
    slices = os.path.join(args.work, stem + ".slices.json")
    result = run([args.binary, "segment", recording, "--calibration", calibration, "-o", slices])
    match = SUMMARY.search(result.stderr)
    if not match:
        raise SystemExit(f"{name}: no summary line in segment's output:\n{result.stderr}")
    segment_slices, frames, failed, repairs = (int(g) for g in match.groups())
    scan_dir = os.path.join(args.work, stem + ".scan")
    run([args.binary, "scan", "--source", "replay:" + recording, "--calibration", calibration,
         "--fast", "--keyframe-angle-deg", "0", "--keyframe-distance-mm", "0", "--out", scan_dir,
         "-q"])
    with open(os.path.join(scan_dir, "scan.json")) as f:
        scan = json.load(f)
    return {"name": name, "frames": frames, "segment_slices": segment_slices, "failed": failed,
            "repairs": repairs, "scan_frames": scan["frames_received"], "scan_slices": scan["slices"],
            "scan_failed": scan["dropped"]["segmentation_failed"],
            "scan_repairs": scan["repairs"]["total"], "slices_path": slices}


def table(rows):
    lines = ["| recording | frames | slices (`segment`) | failed | repairs | slices (`scan`) | "
             "failed (`scan`) | repairs (`scan`) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['name']} | {r['frames']} | {r['segment_slices']} "
                     f"({100 * r['segment_slices'] / r['frames']:.0f} %) | {r['failed']} | "
                     f"{r['repairs']} | {r['scan_slices']} of {r['scan_frames']} | "
                     f"{r['scan_failed']} | {r['scan_repairs']} |")
    return "\n".join(lines)


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("plus_dir", help="a checkout of PlusToolkit/PlusLibData")
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--work", default=os.path.join(root, "out", "bench", "plus_recordings"))
    parser.add_argument("--write-doc", action="store_true",
                        help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    start = (time.monotonic(), os.getloadavg()[0])
    os.makedirs(args.work, exist_ok=True)
    rows = []
    for name, recording, calibration in RECORDINGS:
        rows.append(one_recording(args, root, name, locate(root, args.plus_dir, recording),
                                  locate(root, args.plus_dir, calibration)))
        print(f"{name}: done", file=sys.stderr)
    copies = [r["slices_path"] for r in rows if r["name"].startswith("NwirePhantomFreehand")]
    identical = filecmp.cmp(copies[0], copies[1], shallow=False)
    text = table(rows) + ("\n\nThe `.mha` and `.nrrd` copies of NwirePhantomFreehand give "
                          f"{'byte-identical' if identical else 'DIFFERENT'} slice sets.")
    print(text)
    if args.write_doc:
        write_between_markers(root, "plus_recordings", text + "\n\n" +
                              provenance(root, start[1], time.monotonic() - start[0]))
    short = [r["name"] for r in rows
             if min(r["segment_slices"], r["scan_slices"]) < 0.95 * r["frames"]]
    if short or not identical:
        print(f"\nbelow 95 % of frames: {', '.join(short) or 'none'}; copies identical: "
              f"{identical}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
