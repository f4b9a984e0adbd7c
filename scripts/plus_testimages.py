#!/usr/bin/env python3
"""Tries `sonoshape segment` on every tracked sequence of PlusLibData's TestImages/ and prints,
per file, whether it is read or refused (and why), its frames, the pose chain used and the
calibration given.

  scripts/plus_testimages.py [--mirror DIR] [--binary build/apps/sonoshape] [--every K]

DIR is a git directory of PlusToolkit/PlusLibData (default: the SONOSHAPE_PLUSLIBDATA
environment variable, else /work/.mirror/PlusToolkit+PlusLibData/repo). Without it the script
says so and exits 77 (ctest's "skipped"). Files whose objects the mirror lacks are listed as
absent. Each sweep is segmented every K-th frame (default: about 8 frames per file), so this is
a check that the files read, not a benchmark.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

DEFAULT_MIRROR = "/work/.mirror/PlusToolkit+PlusLibData/repo"
HERE = Path(__file__).resolve().parent.parent
DATA = HERE / "data" / "plus"

# Calibrations PlusLibData holds for its recordings (TestImages/ or data/plus/ copies); other
# recordings get a nominal one (0.2 mm pixels, image origin at the probe), said so in the table.
CALIBRATIONS = [
    (r"^USTC_3NWires_", "TestImages/UsTemplateCalibration_3NWires.results.xml"),
    (r"^USTC_FrameGrabber_", "TestImages/UsTemplateCalibration_FrameGrabber.results.xml"),
    (r"fCal2\.0", "TestImages/FreehandCalibration3NWires_fCal2.0.results.xml"),
    (r"^(fCal_Test|NwirePhantom|WaterTank)", "data/plus/PlusDeviceSet_Server_Sim_NwirePhantom.xml"),
    (r"^(SpinePhantom|outputPlusTransverse|BoneUltrasound)",
     "data/plus/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml"),
]
NOMINAL = {"ImageToProbe": [0.2, 0, 0, 0, 0, 0.2, 0, 0, 0, 0, 0.2, 0, 0, 0, 0, 1]}


def git(mirror, *args, **kw):
    return subprocess.run(["git", "-C", mirror, *args], capture_output=True, **kw)


def library(plus_dir):
    """(fetch, paths) for a PlusLibData checkout or bare git mirror: fetch(path, out_dir) copies
    one file (a .mhd with its pixel file) into out_dir and returns its copy, or None when absent;
    paths lists TestImages/."""
    checkout = Path(plus_dir) / "TestImages"
    if checkout.is_dir():
        def copy(path, out_dir):
            source = Path(plus_dir) / path
            return Path(shutil.copy(source, out_dir / source.name)) if source.is_file() else None
        paths = sorted(str(p.relative_to(plus_dir)) for p in checkout.iterdir())
    else:
        def copy(path, out_dir):
            blob = git(plus_dir, "show", "HEAD:" + path)
            if blob.returncode != 0:
                return None
            out = out_dir / Path(path).name
            out.write_bytes(blob.stdout)
            return out
        listing = git(plus_dir, "ls-tree", "-r", "--name-only", "HEAD", "TestImages", text=True)
        paths = listing.stdout.split()

    def fetch(path, out_dir):
        local = copy(path, out_dir)
        if local is None:
            return None
        head = local.read_bytes()[:65536].decode("latin-1", "replace")
        m = re.search(r"ElementDataFile\s*=\s*(\S+)", head)
        if m and m.group(1) != "LOCAL":  # a .mhd's pixel file, beside it
            copy(str(Path(path).parent / m.group(1)), out_dir)
        return local
    return fetch, paths


def calibration_for(name, fetch, work):
    for pattern, source in CALIBRATIONS:
        if re.search(pattern, name):
            if source.startswith("data/"):
                return HERE / source, source
            got = fetch(source, work)
            if got:
                return got, source
    nominal = work / "nominal.calibration.json"
    nominal.write_text(json.dumps(NOMINAL))
    return nominal, "nominal 0.2 mm/px (PlusLibData has none)"


def header_frames(path):
    head = path.read_bytes()[:65536].decode("latin-1", "replace")
    m = re.search(r"DimSize\s*=\s*\d+\s+\d+\s+(\d+)", head) or re.search(
        r"sizes:\s*\d+\s+\d+\s+(\d+)", head)
    return int(m.group(1)) if m else None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mirror", default=os.environ.get("SONOSHAPE_PLUSLIBDATA", DEFAULT_MIRROR))
    parser.add_argument("--binary", default=str(HERE / "build" / "apps" / "sonoshape"))
    parser.add_argument("--every", type=int, default=0)
    args = parser.parse_args()
    if not any((Path(args.mirror) / p).exists() for p in ("HEAD", ".git", "TestImages")):
        print(f"skipped: no PlusLibData mirror at {args.mirror} (give --mirror DIR or "
              "SONOSHAPE_PLUSLIBDATA)")
        return 77
    if not Path(args.binary).exists():
        print(f"skipped: no sonoshape binary at {args.binary} (build it first)")
        return 77
    fetch, listing = library(args.mirror)
    names = [p for p in listing if re.search(r"\.igs\.(mha|mhd|nrrd)$", p)]
    rows = []

    def report(*row):
        rows.append(row)
        print("\t".join(str(x) for x in row), flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for path in names:
            name = Path(path).name
            local = fetch(path, work)
            if local is None:
                report(name, "absent", "", "", "the mirror lacks this object")
                continue
            frames = header_frames(local) or 0
            every = args.every or max(1, frames // 8)
            calibration, calibration_from = calibration_for(name, fetch, work)
            out = work / "out.slices.json"
            run = subprocess.run([args.binary, "segment", str(local), "--calibration",
                                  str(calibration), "--every", str(every), "-o", str(out)],
                                 capture_output=True, text=True, timeout=900)
            log = run.stdout + run.stderr
            chain = re.search(r"segment: pose (.*?), chosen by (.*)", log)
            chain_text = f"{chain.group(1)} [{chain.group(2)}]" if chain else ""
            if run.returncode == 0:
                summary = re.search(r"segment: (\d+) slices from (\d+) frames", log)
                what = f"{summary.group(1)} slices (every {every})" if summary else ""
                report(name, "read", summary.group(2) if summary else frames, chain_text,
                       f"{what}; calibration: {calibration_from}")
            else:
                error = next((l for l in log.splitlines() if l.startswith("error")), log[-300:])
                error = error.replace(str(work) + "/", "")
                report(name, "refused", frames, chain_text, error.strip())
            local.unlink()
    read = sum(1 for r in rows if r[1] == "read")
    absent = sum(1 for r in rows if r[1] == "absent")
    print(f"{read} of {len(rows)} sequences read ({absent} absent from the mirror)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
