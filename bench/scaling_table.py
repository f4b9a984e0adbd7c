#!/usr/bin/env python3
"""Thread scaling tables (issue 24) from the folder bench/scaling_run.sh writes on a many-core
machine (machine.txt, results.jsonl): per set, the best total time on each thread count, the
speed-up of 16 threads over 1, whether the meshes are the same bit for bit on every thread count,
and, where the run had a `before_bench`, that binary's times on the same machine; then the stages
on 1 and 16 threads, and the online engine's median update.

Usage: python3 bench/scaling_table.py RESULTS_DIR [--write-doc]
Prints Markdown; --write-doc writes it into docs/benchmarks.md between
`<!-- scaling_table:begin -->` and `<!-- scaling_table:end -->`.
"""
import argparse
import json
import os
import statistics

STAGES = [("arrangement_s", "arrangement"),
          ("arrangement_serial_s", "of which serial steps"), ("face_images_s", "face images"),
          ("evaluation_s", "evaluation"), ("completion_s", "completion"),
          ("smoothing_s", "smoothing"), ("mesh_s", "mesh"),
          ("outside_octree_s", "before the octree")]
SET_ORDER = ["random-30", "random-100", "random-200", "random-500", "sweep-100", "sweep-500",
             "blobs-random-200", "sector-random-100"]


def best(runs, key):
    return min(run[key] for run in runs)


def load(folder):
    rows = [json.loads(line) for line in open(os.path.join(folder, "results.jsonl"))]
    for r in rows:
        for run in r["result"].get("runs", []):
            if "total_s" in run:
                # What the stats time before the octree's sampling, its smoothing and the mesher:
                # the slices' preparation, their planes (with the whole arrangement and its face
                # images for sets with unknown regions) and the contour keys.
                run["outside_octree_s"] = (run["total_s"] - run["field_s"] - run["smoothing_s"] -
                                           run["mesh_s"])
    machine = dict(line.split(": ", 1) for line in open(os.path.join(folder, "machine.txt"))
                   .read().splitlines() if ": " in line)
    return rows, machine


def tables(rows, machine):
    offline = {}
    online = {}
    for r in rows:
        target = online if r["name"].startswith("online-") else offline
        target.setdefault((r["binary"], r["name"]), {})[r["threads"]] = r["result"]
    now, before = "sonoshape_device_bench", "before_bench"
    names = sorted({name for _, name in offline}, key=lambda n: (SET_ORDER + [n]).index(n))
    threads = sorted({t for (b, _), by in offline.items() if b == now for t in by})
    has_before = any(b == before for b, _ in offline)
    out = []
    head = ["set", "slices", "cells"]
    if has_before:
        head += ["before: 1 thread s", "before: 16 threads s", "before: speed-up"]
    head += [f"{t} thread{'s' if t > 1 else ''} s" for t in threads]
    head += ["speed-up 16 vs 1", "same meshes on every thread count"]
    out.append("| " + " | ".join(head) + " |")
    out.append("|---" * len(head) + "|")
    for name in names:
        by = offline.get((now, name), {})
        if not by:
            continue
        first = next(iter(by.values()))["runs"][0]
        cells = [f"{name}", f"{first['slices']}", f"{first['cells']:,}".replace(",", " ")]
        if has_before:
            b = offline.get((before, name), {})
            if 1 in b and 16 in b:
                one, sixteen = best(b[1]["runs"], "total_s"), best(b[16]["runs"], "total_s")
                cells += [f"{one:.3f}", f"{sixteen:.3f}", f"{one / sixteen:.1f}"]
            else:
                cells += ["", "", ""]
        cells += [f"{best(by[t]['runs'], 'total_s'):.3f}" if t in by else "" for t in threads]
        if 1 in by and 16 in by:
            cells.append(f"{best(by[1]['runs'], 'total_s') / best(by[16]['runs'], 'total_s'):.1f}")
        else:
            cells.append("")
        hashes = {res["mesh_hash"] for res in by.values()}
        cells.append("yes" if len(hashes) == 1 else f"NO ({len(hashes)} hashes)")
        out.append("| " + " | ".join(cells) + " |")

    out.append("")
    out.append("Stages (best of the runs, s) on 1 and 16 threads:")
    out.append("")
    head = ["set", "threads", "total"] + [label for _, label in STAGES]
    out.append("| " + " | ".join(head) + " |")
    out.append("|---" * len(head) + "|")
    for name in names:
        by = offline.get((now, name), {})
        for t in (1, 16):
            if t not in by:
                continue
            runs = by[t]["runs"]
            # Stages an older binary does not report are left empty.
            out.append(f"| {name} | {t} | {best(runs, 'total_s'):.3f} | " +
                       " | ".join(f"{best(runs, key):.3f}" if all(key in run for run in runs) else ""
                                  for key, _ in STAGES) + " |")

    if online:
        out.append("")
        out.append("Online (one update per slice, the set's file order): median update ms from the "
                   "10th update, and over the last tenth of the slices:")
        out.append("")
        out.append("| binary | set | threads | median ms | last tenth ms | same meshes |")
        out.append("|---|---|---|---|---|---|")
        for (binary, name), by in sorted(online.items(), key=lambda kv: kv[0][0] != now):
            hashes = {res["mesh_hash"] for res in by.values()}
            for t in sorted(by):
                steps = [s["total_s"] for s in by[t]["runs"][0]["steps"]]
                tenth = max(1, len(steps) // 10)
                label = "now" if binary == now else "before"
                out.append(f"| {label} | {name} | {t} | {1e3 * statistics.median(steps[9:]):.1f} | "
                           f"{1e3 * statistics.median(steps[-tenth:]):.1f} | "
                           f"{'yes' if len(hashes) == 1 else 'NO'} |")
    out.append("")
    out.append(f"Measured {machine.get('date', '?')} on {machine.get('cpu', '?')} (the GPU machine "
               f"of the device tool), load average {machine.get('load at start', '?').split()[0]} at "
               f"the start; sonoshape at commit {machine.get('commit', '?')}.")
    return "\n".join(out)


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results")
    parser.add_argument("--write-doc", action="store_true")
    args = parser.parse_args()
    text = tables(*load(args.results))
    print(text)
    if args.write_doc:
        import doc_tables  # beside this file; not needed on the device machine
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        doc_tables.write_between_markers(root, "scaling_table", text)


if __name__ == "__main__":
    main()
