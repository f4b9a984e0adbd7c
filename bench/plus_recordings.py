#!/usr/bin/env python3
"""Segments and replays every tracked sequence of PLUS's test data, as a new user would.

The recordings are the `TestImages/*.igs.{mha,mhd,nrrd}` of PlusToolkit/PlusLibData (BSD-3),
read from a checkout or a bare git mirror of it. Each gets the calibration PlusLibData holds for
it (scripts/plus_testimages.py's table says which; a nominal 0.2 mm/px one where there is none)
and then, with the defaults a user gets (`--preset` through --segment-args):
  sonoshape segment REC --calibration CAL -o WORK/NAME.slices.json
  sonoshape scan --source replay:REC --calibration CAL --realtime --out WORK/NAME.scan -q
  sonoshape_render --size 160 -o docs/images/plus/NAME.png WORK/NAME.scan/label_*.ply
and prints one Markdown table: read or refused (the first error line: why), frames, slices,
unknown share of the sector, `segment`'s seconds, and the real-time replay's slices, update median
and p95, frame-to-mesh p95 and frames dropped for being behind, with the render. The bundled
`.mha` and `.nrrd` copies of the N-wire recording must give byte-identical slice sets.

`--write-doc` puts the table into docs/benchmarks.md between `<!-- plus_recordings:begin -->` and
`<!-- plus_recordings:end -->` and the renders into docs/images/plus/. The exit status is non-zero
when a sequence holding 8-bit B-mode frames and probe poses is refused, or the copies differ.

Usage: bench/plus_recordings.py [PLUSLIBDATA] [--binary build/apps/sonoshape]
           [--render build/bench/sonoshape_render] [--work out/bench/plus_recordings]
           [--only REGEX] [--segment-args "..."] [--write-doc]
PLUSLIBDATA defaults to $SONOSHAPE_PLUSLIBDATA, else /work/.mirror/PlusToolkit+PlusLibData/repo.
"""
import argparse
import filecmp
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

from doc_tables import provenance, write_between_markers

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from plus_testimages import DEFAULT_MIRROR, calibration_for, library  # noqa: E402

SUMMARY = re.compile(r"segment: (\d+) slices from (\d+) frames.*?(\d+)% of the sector unknown")
# Refusals that say the file holds no B-mode frames with probe poses; any other refusal is a
# failure of this benchmark.
NOT_A_TRACKED_BMODE_SWEEP = re.compile(
    r"only 8-bit grey|is not supported; only 8-bit|only single-channel grey|"  # RF, colour
    r"no chain of transforms gives the probe's pose|no frame has a \w+Transform field|"  # no poses
    r"no B-mode images \(a tracker-only buffer\)|DimSize = '0 0 \d+'|"  # tracker buffers
    r"cannot open \S+; copy the pixel file")  # a .mhd whose pixels the mirror lacks


def first_error(log, work):
    line = next((l for l in log.splitlines() if l.startswith("error")), log.strip()[-300:])
    return line.replace(str(work) + "/", "").removeprefix("error: ").strip()


def segment(args, recording, calibration, work):
    slices = work / (recording.name + ".slices.json")
    start = time.monotonic()
    run = subprocess.run([args.binary, "segment", str(recording), "--calibration",
                          str(calibration), "-o", str(slices), *shlex.split(args.segment_args)],
                         capture_output=True, text=True, timeout=1800)
    seconds = time.monotonic() - start
    log = run.stdout + run.stderr
    if run.returncode != 0:
        return {"refused": first_error(log, work)}
    match = SUMMARY.search(log)
    if not match:
        return {"refused": "no summary line in segment's output"}
    return {"slices": int(match.group(1)), "frames": int(match.group(2)),
            "unknown_percent": int(match.group(3)), "segment_s": seconds, "slices_path": slices}


def replay(args, recording, calibration, work, image):
    out = work / (recording.name + ".scan")
    shutil.rmtree(out, ignore_errors=True)
    run = subprocess.run([args.binary, "scan", "--field", "mean-value", "--source", "replay:" + str(recording),
                          "--calibration", str(calibration), "--realtime", "--out", str(out), "-q",
                          *shlex.split(args.segment_args)],
                         capture_output=True, text=True, timeout=1800)
    if run.returncode != 0:
        return {"scan_error": first_error(run.stdout + run.stderr, work)}
    scan = json.loads((out / "scan.json").read_text())
    row = {"scan_slices": scan["slices"], "update_median_ms": scan["update_ms"]["median"],
           "update_p95_ms": scan["update_ms"]["p95"],
           "latency_p95_ms": 1e3 * scan["latency_s"]["p95"],
           "behind": scan["dropped"]["segmentation_behind"]
           + scan["dropped"]["reconstruction_behind"]}
    meshes = sorted(str(p) for p in out.glob("label_*.ply"))
    if meshes:
        image.parent.mkdir(parents=True, exist_ok=True)
        rendered = subprocess.run([args.render, "--size", "160", "-o", str(image), *meshes],
                                  capture_output=True, text=True)
        row["render"] = image if rendered.returncode == 0 else None
    return row


def one_recording(args, fetch, path, work):
    name = str(Path(path).relative_to("TestImages"))  # e.g. Linux/NrrdSample.igs.nrrd
    local = fetch(path, work)
    if local is None:
        return {"name": name, "absent": True}
    calibration, calibration_from = calibration_for(Path(path).name, fetch, work)
    row = {"name": name, "calibration": calibration_from}
    row.update(segment(args, local, calibration, work))
    if "refused" not in row:
        image = Path(args.images) / (re.sub(r"\W+", "_", name.split(".igs")[0]) + ".png")
        row.update(replay(args, local, calibration, work, image))
    return row


def cell(row, key, fmt="{:.0f}"):
    return fmt.format(row[key]) if key in row else "–"


def table(rows, doc_images):
    lines = ["| recording | read | frames | slices | unknown | `segment` s | replay: slices | "
             "update median / p95 ms | frame-to-mesh p95 ms | behind | result |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.get("absent"):
            lines.append(f"| {r['name']} | absent from the mirror (object missing) |"
                         + " |" * 9)
            continue
        if "refused" in r:
            lines.append(f"| {r['name']} | refused: {r['refused']} |" + " |" * 9)
            continue
        render = (f"![{r['name']}]({os.path.relpath(r['render'], doc_images)})"
                  if r.get("render") else "no mesh")
        scan = (f"{cell(r, 'scan_slices')} | {cell(r, 'update_median_ms')} / "
                f"{cell(r, 'update_p95_ms')} | {cell(r, 'latency_p95_ms')} | {cell(r, 'behind')}"
                if "scan_error" not in r else f"failed: {r['scan_error']} | | |")
        lines.append(f"| {r['name']} | read ({r['calibration']}) | {r['frames']} | {r['slices']} | "
                     f"{r['unknown_percent']} % | {r['segment_s']:.1f} | {scan} | {render} |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("plus_dir", nargs="?",
                        default=os.environ.get("SONOSHAPE_PLUSLIBDATA", DEFAULT_MIRROR))
    parser.add_argument("--binary", default=str(ROOT / "build" / "apps" / "sonoshape"))
    parser.add_argument("--render", default=str(ROOT / "build" / "bench" / "sonoshape_render"))
    parser.add_argument("--work", default=str(ROOT / "out" / "bench" / "plus_recordings"))
    parser.add_argument("--only", default="", help="recordings whose name matches this regex")
    parser.add_argument("--segment-args", default="",
                        help="extra options for segment and scan (e.g. \"--preset wires\")")
    parser.add_argument("--write-doc", action="store_true",
                        help="write the table into docs/benchmarks.md, renders to docs/images/plus")
    args = parser.parse_args()
    args.images = (ROOT / "docs" / "images" / "plus") if args.write_doc else (
        Path(args.work) / "images")
    if args.write_doc and (args.only or args.segment_args):
        raise SystemExit("--write-doc writes the table of every recording with the defaults; "
                         "drop --only and --segment-args")
    start = (time.monotonic(), os.getloadavg()[0])
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    fetch, names = library(args.plus_dir)
    names = [p for p in names if re.search(r"\.igs\.(mha|mhd|nrrd)$", p)
             and re.search(args.only, Path(p).name)]
    rows = []
    for path in names:
        rows.append(one_recording(args, fetch, path, work))
        r = rows[-1]
        print(f"{r['name']}: " + ("absent" if r.get("absent") else r.get("refused", "read")),
              file=sys.stderr, flush=True)
    bundled = [ROOT / "data/plus/NwirePhantomFreehand.igs.mha",
               ROOT / "data/plus/NwirePhantomFreehand.igs.nrrd"]
    copies = [segment(args, b, ROOT / "data/plus/PlusDeviceSet_Server_Sim_NwirePhantom.xml", work)
              for b in bundled]
    identical = all("slices_path" in c for c in copies) and filecmp.cmp(
        copies[0]["slices_path"], copies[1]["slices_path"], shallow=False)
    read = sum(1 for r in rows if "frames" in r)
    absent = sum(1 for r in rows if r.get("absent"))
    text = (table(rows, ROOT / "docs") +
            f"\n\n{read} of {len(rows)} sequences read, {len(rows) - read - absent} refused, "
            f"{absent} absent from the mirror. The bundled `.mha` and `.nrrd` copies of "
            f"NwirePhantomFreehand give {'byte-identical' if identical else 'DIFFERENT'} slice "
            "sets.")
    print(text)
    if args.write_doc:
        write_between_markers(str(ROOT), "plus_recordings", text + "\n\n" +
                              provenance(str(ROOT), start[1], time.monotonic() - start[0]))
    wrongly_refused = [r["name"] for r in rows if "refused" in r
                       and not NOT_A_TRACKED_BMODE_SWEEP.search(r["refused"])]
    if wrongly_refused or not identical:
        print(f"\nrefused though tracked B-mode: {', '.join(wrongly_refused) or 'none'}; copies "
              f"identical: {identical}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
