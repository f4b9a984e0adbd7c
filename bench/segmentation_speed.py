#!/usr/bin/env python3
"""Per-frame segmentation time by stage at 820x616, and a 30 fps live scan of such frames.

Runs
  sonoshape simulate --width-px 820 --height-px 616 --frames N --frame-rate 30 --seed 1
                     -o WORK/sim820.igs.mha
  sonoshape_seg_speed SWEEP [--calibration FILE] [--threads 1] [--method graph-cut] --repeat R
                      --json OUT
for the PLUS spine recording (data/plus/SpinePhantomFreehand.igs.mha with its calibration) and the
simulated sweep, with OpenCV's default thread count and with 1 thread, and the graph cut (image
alone, no prior) with the default thread count (and the same with --baseline, a
sonoshape_seg_speed built from an earlier commit, for a before/after under the same load), then
  sonoshape simulate ... --frames 30*S --frame-rate 30 -o WORK/scan820.igs.mha
  sonoshape scan --source replay:WORK/scan820.igs.mha --realtime -o WORK/scan
  sonoshape scan --source replay:WORK/scan820.igs.mha --realtime --method graph-cut
                 -o WORK/scan_graph_cut
  sonoshape scan --source sim:default --width-px 820 --height-px 616 --frame-rate 30
                 --sweep-s S --realtime -o WORK/scan_sim
and prints Markdown tables: the stages' mean wall time per frame (filter: median and masked
Gaussian; confidence: dark fraction, shadows, margin; classify: depth trend, nearest mean, bone
sections, the graph cut; cleaning: blooming correction, opening, small components, diagonal
repair, output maps; contours: segmentation::make_slice, i.e. tracing, simplification and the validity
check), the whole frame's mean, 90th percentile, best of the repeats (each frame's fastest pass,
averaged) and processor time (all threads; on a shared machine the wall time includes waiting for
a core), and the scans' drops by reason. `--write-doc` puts them into docs/benchmarks.md between
`<!-- segmentation_speed:begin -->` and `<!-- segmentation_speed:end -->`.
The exit status is non-zero when a command fails.

Usage: bench/segmentation_speed.py [--binary build/apps/sonoshape]
                                   [--speed-binary build/bench/sonoshape_seg_speed]
                                   [--baseline PATH] [--baseline-name TEXT]
                                   [--work out/bench/segmentation_speed] [--repeat 3]
                                   [--sim-frames 40] [--scan-s 10] [--write-doc]
"""
import argparse
import json
import os
import platform
import subprocess
import time

from doc_tables import write_between_markers

PLUS = ("data/plus/SpinePhantomFreehand.igs.mha",
        "data/plus/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml")
SIZE = ["--width-px", "820", "--height-px", "616"]
STAGES = ["filter", "confidence", "classify", "cleaning", "contours"]
DROPS = ["source", "segmentation_behind", "reconstruction_behind", "pose_invalid",
         "segmentation_failed"]


def run(cmd, what):
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        lines = (result.stderr or result.stdout).strip().splitlines()
        raise SystemExit(f"{what} failed: {lines[-1] if lines else result.returncode}")
    return result


def speed(binary, sweep, calibration, threads, method, repeat, out):
    cmd = [binary, sweep, "--repeat", str(repeat), "--method", method, "--json", out]
    if calibration:
        cmd += ["--calibration", calibration]
    if threads:
        cmd += ["--threads", str(threads)]
    run(cmd, f"{os.path.basename(binary)} {sweep}")
    with open(out) as f:
        return json.load(f)


def scan(binary, source_args, out):
    run([binary, "scan", "--field", "mean-value", *source_args, "--realtime", "-o", out, "-q"], f"scan {source_args[1]}")
    with open(os.path.join(out, "scan.json")) as f:
        return json.load(f)


def speed_table(rows):
    lines = ["| frames | method | build | OpenCV threads | " + " | ".join(STAGES) +
             " | frame mean | frame p90 | best of repeats | processor time |",
             "|---|---|---|---|" + "---|" * len(STAGES) + "---|---|---|---|"]
    for name, build, r in rows:
        stages = " | ".join(f"{r['stage_ms'][s]:.1f}" for s in STAGES)
        lines.append(f"| {name} | {r['method']} | {build} | {r['opencv_threads']} | {stages} | "
                     f"**{r['frame_ms']['mean']:.1f}** | {r['frame_ms']['p90']:.1f} | "
                     f"{r['frame_ms']['best_of_repeats_mean']:.1f} | "
                     f"**{r['frame_ms']['cpu_mean']:.1f}** |")
    return "\n".join(lines)


def scan_table(rows):
    lines = ["| source (30 fps, 820x616) | frames received | slices | " +
             " | ".join(f"dropped: {d}" for d in DROPS) + " |",
             "|---|---|---|" + "---|" * len(DROPS)]
    for name, s in rows:
        drops = " | ".join(str(s["dropped"].get(d, 0)) for d in DROPS)
        lines.append(f"| {name} | {s['frames_received']} | {s['slices']} | {drops} |")
    return "\n".join(lines)


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--speed-binary",
                        default=os.path.join(root, "build", "bench", "sonoshape_seg_speed"))
    parser.add_argument("--baseline", help="a sonoshape_seg_speed of an earlier commit")
    parser.add_argument("--baseline-name", default="before")
    parser.add_argument("--work", default=os.path.join(root, "out", "bench", "segmentation_speed"))
    parser.add_argument("--repeat", type=int, default=3, help="passes over each sweep")
    parser.add_argument("--sim-frames", type=int, default=40)
    parser.add_argument("--scan-s", type=float, default=10.0, help="length of the scans (s)")
    parser.add_argument("--write-doc", action="store_true")
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)
    start, load_before = time.time(), os.getloadavg()[0]

    sim = os.path.join(args.work, "sim820.igs.mha")
    run([args.binary, "simulate", *SIZE, "--frames", str(args.sim_frames), "--frame-rate", "30",
         "--seed", "1", "-o", sim], "simulate")
    inputs = [("PLUS spine", os.path.join(root, PLUS[0]), os.path.join(root, PLUS[1])),
              ("simulated", sim, None)]
    builds = [("this" if not args.baseline else "after", args.speed_binary)]
    if args.baseline:
        builds.insert(0, (args.baseline_name, args.baseline))
    rows = []
    for name, sweep, calibration in inputs:
        for method, threads in [("threshold", None), ("threshold", 1), ("graph-cut", None)]:
            for build, binary in builds:
                out = os.path.join(args.work, f"{name.split()[0]}_{method}_{build.split()[0]}_"
                                              f"{threads or 'default'}.json")
                rows.append((name, build, speed(binary, sweep, calibration, threads, method,
                                                 args.repeat, out)))

    frames = str(int(round(30 * args.scan_s)))
    recorded = os.path.join(args.work, "scan820.igs.mha")
    run([args.binary, "simulate", *SIZE, "--frames", frames, "--frame-rate", "30", "--seed", "1",
         "-o", recorded], "simulate (scan)")
    replay = ["--source", f"replay:{recorded}"]
    scans = [("replay of a simulated sweep", scan(args.binary, replay,
                                                  os.path.join(args.work, "scan"))),
             ("the same, --method graph-cut",
              scan(args.binary, [*replay, "--method", "graph-cut"],
                   os.path.join(args.work, "scan_graph_cut"))),
             ("sim:default (rendered live)",
              scan(args.binary, ["--source", "sim:default", *SIZE, "--frame-rate", "30",
                                 "--sweep-s", str(args.scan_s)],
                   os.path.join(args.work, "scan_sim")))]

    commit = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip() or "unknown"
    text = "\n\n".join([
        speed_table(rows),
        scan_table(scans),
        f"Milliseconds per frame (stages: mean wall time; processor time: all threads). "
        f"--repeat {args.repeat}, {args.sim_frames} simulated frames, {args.scan_s:g} s scans; "
        f"sonoshape at commit {commit}; {os.cpu_count()} cores ({platform.machine()}, "
        f"{platform.system()}), load average {load_before:.1f} at the start and "
        f"{os.getloadavg()[0]:.1f} at the end, niceness {os.nice(0)}; "
        f"{time.time() - start:.0f} s in all."])
    print(text)
    if args.write_doc:
        write_between_markers(root, "segmentation_speed", text)


if __name__ == "__main__":
    main()
