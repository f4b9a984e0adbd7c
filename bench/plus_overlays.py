#!/usr/bin/env python3
"""Pictures of the real PLUS recordings segmented by the graph cut, for docs/segmentation.md.

For the spine phantom sweep (bundled in data/plus/) and BoneUltrasound_L14 (read from a
PlusToolkit/PlusLibData checkout you pass) this runs
  sonoshape segment REC --calibration XML --method graph-cut --prior reconstruction
                    --overlays WORK/NAME -o WORK/NAME.slices.json
and copies the overlay of one frame (the middle one unless --frame) to
docs/images/plus_<name>_graph_cut.png: the B-mode frame with the outline of every label
(no truth exists for real data) and the unknown area tinted.

Usage: bench/plus_overlays.py PLUSLIBDATA [--binary build/apps/sonoshape]
                              [--work out/bench/plus_overlays]
"""
import argparse
import os
import shutil
import subprocess
import sys

SPINE = ("spine", "data/plus/SpinePhantomFreehand.igs.mha",
         "data/plus/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml")
BONE = ("bone", "TestImages/BoneUltrasound_L14.igs.mha",
        "ConfigFiles/Testing/BoneUltrasound_L14_config.xml")


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("plus_lib_data", help="a PlusToolkit/PlusLibData checkout")
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--work", default=os.path.join(root, "out", "bench", "plus_overlays"))
    args = parser.parse_args()
    for name, recording, calibration in (SPINE, BONE):
        base = root if recording.startswith("data/") else args.plus_lib_data
        folder = os.path.join(args.work, name)
        shutil.rmtree(folder, ignore_errors=True)
        cmd = [args.binary, "segment", os.path.join(base, recording), "--calibration",
               os.path.join(base if calibration.startswith("ConfigFiles") else root, calibration),
               "--method", "graph-cut", "--prior", "reconstruction", "--overlays", folder,
               "-o", os.path.join(args.work, name + ".slices.json")]
        result = subprocess.run(cmd, capture_output=True, text=True)
        if result.returncode != 0:
            sys.stderr.write(" ".join(cmd) + "\n" + result.stderr)
            return 1
        pictures = sorted(os.listdir(folder))
        picked = pictures[len(pictures) // 2]
        target = os.path.join(root, "docs", "images", f"plus_{name}_graph_cut.png")
        shutil.copyfile(os.path.join(folder, picked), target)
        print(f"{name}: {len(pictures)} frames, {picked} -> {os.path.relpath(target, root)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
