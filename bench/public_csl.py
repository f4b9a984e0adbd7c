#!/usr/bin/env python3
"""Reconstructs every public .csl cross-section dataset in a folder and scores those with a reference.

The collection is the `Data/` folder of the OReX repository (haimsaw/OReX on GitHub): 23 .csl files
of the neural cross-section papers, 10 with a reference surface (`reference/<name>_scaled.stl`).
It has no licence, so sonoshape does not ship it: clone it and pass its folder.

For each .csl file (found recursively, sorted by name) this runs
  sonoshape reconstruct FILE -o WORK/NAME --stats WORK/NAME.stats.json
and, where a reference mesh is found,
  sonoshape evaluate --recon WORK/NAME --truth 1:REF --slices FILE --json WORK/NAME.eval.json
then prints one Markdown table: planes, materials, repairs by kind, seconds, peak RSS, whether every
mesh is closed, manifold and oriented, and IoU / mean / Hausdorff distance (% of the evaluation
box diagonal) beside the closest-point baseline's IoU. `--write-doc` puts the table into
docs/benchmarks.md between the markers `<!-- public_csl:begin -->` and `<!-- public_csl:end -->`.
The exit status is non-zero when a file fails to reconstruct or gives a mesh that is not closed.

Usage: bench/public_csl.py DIR [--binary build/apps/sonoshape] [--work out/bench/public_csl]
                           [--only NAME ...] [--write-doc]
"""
import argparse
import collections
import json
import os
import re
import subprocess
import sys

from doc_tables import provenance, write_between_markers
import time

# Reference surfaces whose name is not <csl name>_scaled.stl: the simplified lamp shares the
# reference of the lamp it was simplified from.
REFERENCE_OF = {"lamp004_fixed_simplified": "lamp004_fixed"}


def find_files(root):
    csl, stl = {}, {}
    for folder, _, names in os.walk(root):
        for name in names:
            path = os.path.join(folder, name)
            stem, ext = os.path.splitext(name)
            if ext.lower() == ".csl":
                csl[stem] = path
            elif ext.lower() == ".stl":
                stl[re.sub(r"_scaled$", "", stem)] = path
    return csl, stl


def header_counts(path):
    """(planes, nLabels) from the file's header, as written."""
    with open(path) as f:
        tokens = f.read(256).split()
    return int(tokens[1]), int(tokens[2])


def run_timed(cmd):
    start = time.monotonic()
    result = subprocess.run(cmd, capture_output=True, text=True)
    return result, time.monotonic() - start


def one_file(args, name, csl_path, reference):
    out = os.path.join(args.work, name)
    stats_path = out + ".stats.json"
    for stale in (stats_path, out + ".eval.json"):
        if os.path.exists(stale):
            os.remove(stale)
    row = {"name": name, "reference": reference is not None}
    row["planes"], row["declared_labels"] = header_counts(csl_path)
    result, seconds = run_timed([args.binary, "reconstruct", "--field", "mean-value", csl_path, "-o", out,
                                 "--stats", stats_path, "-q"])
    row["exit"] = result.returncode
    row["seconds"] = seconds
    if result.returncode != 0:
        row["error"] = result.stderr.strip().splitlines()[0] if result.stderr.strip() else "?"
        return row
    with open(stats_path) as f:
        stats = json.load(f)
    row["slices"] = stats["slices"]
    row["peak_rss_mb"] = stats["peak_rss_mb"]
    row["repairs"] = collections.Counter(r["kind"] for r in stats.get("repairs", []))
    row["meshes"] = stats["meshes"]
    row["closed"] = all(m["closed_manifold_oriented"] for m in stats["meshes"])
    if reference:
        eval_path = out + ".eval.json"
        result, _ = run_timed([args.binary, "evaluate", "--recon", out, "--truth",
                               f"1:{reference}", "--slices", csl_path, "--json", eval_path, "-q"])
        if result.returncode != 0:
            row["eval_error"] = result.stderr.strip()
            print(f"{name}: evaluate failed: {row['eval_error']}", file=sys.stderr)
        else:
            with open(eval_path) as f:
                row["scores"] = json.load(f)["labels"][0]
    return row


def cell(value, digits):
    return "–" if value is None else f"{value:.{digits}f}"


def table(rows):
    lines = ["| file | planes | materials | repairs | s | peak RSS MB | closed manifold oriented | "
             "IoU | baseline IoU | mean dist % | Hausdorff % |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["exit"] != 0:
            lines.append(f"| {r['name']} | {r['planes']} | – | – | {r['seconds']:.1f} | – | "
                         f"FAILED: {r['error']} | | | | |")
            continue
        repairs = ", ".join(f"{kind} {count}" for kind, count in sorted(r["repairs"].items()))
        materials = f"{len(r['meshes'])} of {r['declared_labels'] - 1}"
        s = r.get("scores")
        iou = base = mean = haus = None
        if s:
            iou, base = s["iou"], s["baseline_iou"]
            mean, haus = s["mean_surface_distance_percent"], s["hausdorff_distance_percent"]
        scored = [cell(iou, 4), cell(base, 4), cell(mean, 3), cell(haus, 2)]
        if "eval_error" in r:
            scored = ["evaluation failed"] + [""] * 3
        lines.append(
            f"| {r['name']} | {r['slices']} | {materials} | {repairs or 'none'} | "
            f"{r['seconds']:.1f} | {r['peak_rss_mb']:.0f} | {'yes' if r['closed'] else 'NO'} | "
            f"{' | '.join(scored)} |")
    return "\n".join(lines)


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dir", help="folder holding the .csl files (and reference .stl files)")
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--work", default=os.path.join(root, "out", "bench", "public_csl"))
    parser.add_argument("--only", nargs="*", help="names (without .csl) to run")
    parser.add_argument("--write-doc", action="store_true",
                        help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    start = (time.monotonic(), os.getloadavg()[0])
    os.makedirs(args.work, exist_ok=True)
    csl, stl = find_files(args.dir)
    if not csl:
        raise SystemExit(f"no .csl file under {args.dir}")
    rows = []
    for name in sorted(csl, key=str.lower):
        if args.only and name not in args.only:
            continue
        if os.path.getsize(csl[name]) == 0:
            print(f"{name}: empty file (not fetched?), skipped", file=sys.stderr)
            continue
        reference = stl.get(REFERENCE_OF.get(name, name))
        if reference and os.path.getsize(reference) == 0:
            reference = None
        row = one_file(args, name, csl[name], reference)
        rows.append(row)
        status = "ok" if row["exit"] == 0 else "FAILED"
        print(f"{name}: {status} in {row['seconds']:.1f} s", file=sys.stderr)
    text = table(rows)
    print(text)
    if args.write_doc:
        write_between_markers(root, "public_csl", text + "\n\n" +
                              provenance(root, start[1], time.monotonic() - start[0]))
    failed = [r["name"] for r in rows
              if r["exit"] != 0 or not r.get("closed", False) or "eval_error" in r]
    if failed:
        print(f"\nnot reconstructed into closed meshes (or not evaluated): {', '.join(failed)}",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
