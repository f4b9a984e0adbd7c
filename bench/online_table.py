#!/usr/bin/env python3
"""Online reconstruction benchmark (issue: online engine): the paper's Table II for online
additions, the median update time, the ratio to a full rebuild, memory, and how the time per
slice grows up to 150 slices (table and PNG plot).

For every model in MODELS it cuts a random set (100 planes), a sweep-like set (150 planes) and a
sweep of 100 planes whose every slice has a 60-degree sector field of view (the rest unknown),
feeds each to `sonoshape reconstruct --online --stats` (one update per slice, default depth), and
reconstructs the first N slices of each set offline (the same box) for N in CHECKPOINTS. Every
online sequence and every rebuild runs --repeats times (default 3; each repeat runs the online
sequence, then its rebuilds) and the tables take the median of each timing.

Usage: python3 bench/online_table.py [--bin build/apps/sonoshape] [--models horse,spot] [--repeats 3]
       [--plot docs/images/online_update_times.png] [--reuse] [--quick] [--write-doc]
Prints Markdown tables on stdout; --write-doc puts them, with the commit, machine and load, into
docs/benchmarks.md between `<!-- online_table:begin -->` and `<!-- online_table:end -->`. Run it
from the repository root. Needs python3-matplotlib for the plot (skipped with a note when it is
missing). --quick: the horse only, one repeat, no plot.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from doc_tables import provenance, write_between_markers

MODELS = {"horse": "horse.ply", "spot": "spot.obj", "cheburashka": "cheburashka.obj"}
# name suffix -> (planes, count, extra `slice` arguments). The sector sweep is the bedside case:
# every frame sees only its 60-degree sector (aimed to cover the organ); the rest of each plane is
# unknown and completed (issue: unknown regions).
FAMILIES = {"random100": ("random", 100, []), "sweep150": ("sweep", 150, []),
            "sweep100_sector": ("sweep", 100, ["--fov", "sector", "--fov-aim", "cover"])}
CHECKPOINTS = [5, 10, 40, 100, 150]
RATIO_EVERY = 5  # the update / rebuild ratio is also sampled at slices 10, 15, 20, ...
STAGES = ["arrangement_s", "face_images_s", "field_s", "smoothing_s", "mesh_s", "total_s"]
# Timing fields of the stats that --repeats takes the median of.
TIMES = STAGES + ["evaluation_s", "completion_s"]


def median_stats(runs):
    """The first run's stats with every timing field replaced by its median over the runs."""
    merged = dict(runs[0])
    for key in TIMES:
        if key in merged:
            merged[key] = statistics.median(r[key] for r in runs)
    return merged


def run(args):
    result = subprocess.run(args, capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit("failed: " + " ".join(args) + "\n" + result.stdout + result.stderr)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bin", default="build/apps/sonoshape")
    parser.add_argument("--models", default=",".join(MODELS))
    parser.add_argument("--work", default="out/bench/online")
    parser.add_argument("--plot", default="docs/images/online_update_times.png")
    parser.add_argument("--repeats", type=int, default=3,
                        help="runs of every online sequence and rebuild; timings are their medians "
                             "(single runs on a busy 2-core machine move a ratio by up to 0.1)")
    parser.add_argument("--reuse", action="store_true",
                        help="keep the stats files a previous run left in --work and run only what is "
                             "missing (prints that run's tables again)")
    parser.add_argument("--quick", action="store_true", help="the horse only, one repeat, no plot")
    parser.add_argument("--write-doc", action="store_true",
                        help="write the tables into docs/benchmarks.md between the online_table markers")
    options = parser.parse_args()
    if options.quick:
        options.models, options.repeats, options.plot = "horse", 1, ""
    run_start = (time.monotonic(), os.getloadavg()[0])
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    os.makedirs(options.work, exist_ok=True)

    def run_for(path, args):
        """Runs args, which write `path`, unless --reuse and `path` exists."""
        if not (options.reuse and os.path.exists(path)):
            run(args)
    table_rows, summary_rows, split_rows, growth = [], [], [], {}
    for model in options.models.split(","):
        for suffix, (family, count, extra) in FAMILIES.items():
            name = f"{model}_{suffix}"
            slices = os.path.join(options.work, name + ".slices.json")
            run_for(slices, [options.bin, "slice", "--mesh", f"1:data/models/{MODELS[model]}:{model}", "--planes", family,
                 "--count", str(count), "--seed", "1", "--size-mm", "150", "-o", slices, "--skip-invalid", "-q"] + extra)
            data = json.load(open(slices))
            slice_count = len(data["slices"])  # planes that cut the model (--skip-invalid)
            # The slice counts whose offline rebuild the tables compare an update with.
            rebuild_counts = sorted({n for n in CHECKPOINTS if n <= slice_count} |
                                    set(range(10, slice_count + 1, RATIO_EVERY)))
            for n in rebuild_counts:  # same bounds: the same box
                json.dump(dict(data, slices=data["slices"][:n]),
                          open(os.path.join(options.work, f"{name}_first{n}.slices.json"), "w"))
            # Each repeat runs the online sequence and then every rebuild, so that an update and the
            # rebuild it is divided by are measured minutes apart at most, not a whole set apart (the
            # machine's speed drifts; bench/online_ratio_pairs.py does the same for two builds).
            online_runs, rebuild_runs = [], {n: [] for n in rebuild_counts}
            for repeat in range(options.repeats):
                stats_path = os.path.join(options.work, f"{name}.online{repeat}.json")
                run_for(stats_path, [options.bin, "reconstruct", "--field", "mean-value", slices, "-o", os.path.join(options.work, name + "_online"),
                                     "--online", "--stats", stats_path, "-q"])
                online_runs.append(json.load(open(stats_path)))
                for n in rebuild_counts:
                    offline_path = os.path.join(options.work, f"{name}_first{n}.offline{repeat}.json")
                    run_for(offline_path, [options.bin, "reconstruct", "--field", "mean-value",
                                           os.path.join(options.work, f"{name}_first{n}.slices.json"), "-o",
                                           os.path.join(options.work, f"{name}_first{n}"), "--stats", offline_path, "-q"])
                    rebuild_runs[n].append(json.load(open(offline_path)))
            online = median_stats(online_runs)
            steps = [median_stats([r["steps"][i] for r in online_runs]) for i in range(len(online_runs[0]["steps"]))]
            growth[name] = [s["total_s"] for s in steps]
            rebuilds = {n: median_stats(runs) for n, runs in rebuild_runs.items()}
            ratios = []
            for n in CHECKPOINTS:
                if n > len(steps):
                    continue
                offline = rebuilds[n]
                step = steps[n - 1]
                ratio = step["total_s"] / offline["total_s"]
                ratios.append(ratio)
                table_rows.append(
                    f"| {name} | {n} | " + " | ".join(f"{step[k]:.3f}" for k in STAGES) +
                    f" | {step['cells_changed']} / {step['cells']} | {step['field_evaluations']} | "
                    f"{offline['total_s']:.3f} | {ratio:.2f} |")
            # The update at every RATIO_EVERY-th slice from 10 on against a rebuild of as many slices.
            # The evaluation share is the zone itself: an update must evaluate again every sampled
            # vertex in the cells its plane split (their field changed).
            sampled, evaluation_shares, evaluation_time_shares, evaluation_time_ratios = [], [], [], []
            pass_shares, pass_ratios = [], []
            for n in range(10, len(steps) + 1, RATIO_EVERY):
                offline = rebuilds[n]
                sampled.append(steps[n - 1]["total_s"] / offline["total_s"])
                evaluation_shares.append(steps[n - 1]["field_evaluations"] / offline["field_evaluations"])
                # The update's own evaluation seconds against the whole rebuild: its ratio if the
                # octree, smoothing and mesh passes (global, see docs/engine.md) cost nothing.
                evaluation_time_shares.append(steps[n - 1]["evaluation_s"] / offline["total_s"])
                # ... and against the rebuild's evaluation seconds: with the passes' ratio below,
                # what faster evaluations or faster passes, shared by updates and rebuilds, would
                # make of the update / rebuild ratio (docs/benchmarks.md works it out).
                evaluation_time_ratios.append(steps[n - 1]["evaluation_s"] / offline["evaluation_s"])
                # The rest of the update's field, smoothing and mesh time: the octree, smoothing and
                # mesh passes, against the whole rebuild and against the rebuild's own passes.
                def passes(stats):
                    return stats["total_s"] - stats["evaluation_s"] - stats["arrangement_s"] - stats["face_images_s"]
                pass_shares.append(passes(steps[n - 1]) / offline["total_s"])
                pass_ratios.append(passes(steps[n - 1]) / passes(offline))
            later = [s["total_s"] for s in steps if s["step"] >= 10]
            rss_100 = steps[min(100, len(steps)) - 1]["peak_rss_mb"]
            summary_rows.append(
                f"| {name} | {len(steps)} | {1000 * statistics.median(later):.0f} | "
                f"{1000 * statistics.quantiles(later, n=10)[8]:.0f} | {1000 * max(later):.0f} | "
                f"{statistics.median(ratios):.2f} | {statistics.median(sampled):.3f} "
                f"({sum(r < 0.2 for r in sampled)} of {len(sampled)} under 0.2) | "
                f"{statistics.median(evaluation_shares):.2f} ({sum(r < 0.2 for r in evaluation_shares)} of "
                f"{len(evaluation_shares)} under 0.2) | {statistics.median(evaluation_time_shares):.2f} | "
                f"{rss_100:.0f} | {online['total_s']:.1f} |")
            split_rows.append(
                f"| {name} | {statistics.median(sampled):.3f} | {statistics.median(evaluation_time_shares):.2f} | "
                f"{statistics.median(evaluation_time_ratios):.2f} | {statistics.median(pass_shares):.2f} | "
                f"{statistics.median(pass_ratios):.2f} |")

    lines = []

    def emit(text=""):
        lines.append(text)
    emit("### Online additions (Table II of the paper, online)\n")
    emit("| set | slice | arrangement s | face images s | field s | smoothing s | mesh s | update total s "
          "| cells changed / cells | field evaluations | full rebuild s | update / rebuild |")
    emit("|---|---|---|---|---|---|---|---|---|---|---|---|")
    emit("\n".join(table_rows))
    emit("\n### Update time per set (slices 10 and later)\n")
    emit("| set | slices | median update ms | 90th percentile ms | max ms | median update / rebuild "
          "(checkpoints) | median update / rebuild (every 5th slice from 10) | median field evaluations "
          "update / rebuild (same slices) | median update evaluation s / rebuild s (same slices) | "
          "peak RSS after 100 slices MB | all updates s |")
    emit("|---|---|---|---|---|---|---|---|---|---|---|")
    emit("\n".join(summary_rows))
    emit("\n### Where an update's time goes, against a rebuild (every 5th slice from 10, medians)\n")
    emit("| set | update / rebuild | update evaluations s / rebuild s | update evaluations s / rebuild "
          "evaluations s | update passes s / rebuild s | update passes s / rebuild passes s |")
    emit("|---|---|---|---|---|---|")
    emit("\n".join(split_rows))
    emit("\n### Time per slice against the slice count (mean of each block of 10 slices, ms)\n")
    names = list(growth)
    emit("| slices | " + " | ".join(names) + " |")
    emit("|---|" + "---|" * len(names))
    longest = max(len(v) for v in growth.values())
    for start in range(0, longest, 10):
        cells = []
        for n in names:
            block = growth[n][start:start + 10]
            cells.append(f"{1000 * statistics.mean(block):.0f}" if block else "")
        emit(f"| {start + 1}-{start + 10} | " + " | ".join(cells) + " |")
    print("\n".join(lines))
    if options.write_doc:
        line = provenance(root, run_start[1], time.monotonic() - run_start[0])
        write_between_markers(root, "online_table", "\n".join(lines) + "\n\n" + line +
                              f" --repeats {options.repeats}.")
    if not options.plot:
        return
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("\n(plot skipped: install python3-matplotlib)", file=sys.stderr)
        return
    figure, axis = plt.subplots(figsize=(8, 4.5), dpi=110)
    for n in names:
        axis.plot(range(1, len(growth[n]) + 1), [1000 * t for t in growth[n]], label=n, linewidth=1)
    axis.axhline(250, color="grey", linestyle="--", linewidth=0.8, label="250 ms target")
    axis.set_xlabel("slices in the reconstruction")
    axis.set_ylabel("update time (ms)")
    axis.set_yscale("log")
    axis.set_title("sonoshape online update per added slice (2 cores, default depth)")
    axis.legend(fontsize=8, ncol=2)
    axis.grid(True, which="both", linewidth=0.3)
    figure.tight_layout()
    os.makedirs(os.path.dirname(options.plot), exist_ok=True)
    figure.savefig(options.plot)
    print(f"\nplot: {options.plot}", file=sys.stderr)


if __name__ == "__main__":
    main()
