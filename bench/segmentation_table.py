#!/usr/bin/env python3
"""Scores the segmentation of simulated sweeps against the simulator's truth, beside perfect labels.

For each case (a phantom, a probe, a trajectory and a tracker noise level) this runs
  sonoshape simulate [case options] --frames N --seed S -o WORK/CASE.igs.mha --truth WORK/CASE_truth
  sonoshape segment WORK/CASE.igs.mha METHOD --truth-labels WORK/CASE_truth/labels.mha
                    --report WORK/CASE.M.seg.json --every K -o WORK/CASE.M.slices.json
                    (METHOD: `--method threshold`, the baseline; `--method graph-cut --prior
                    none`; `--method graph-cut --prior reconstruction`; the graph cuts with
                    `--seed L:X,Y,Z` per organ, its truth mesh's vertex centroid, as a
                    clinician's one click on each organ)
  sonoshape segment WORK/CASE.igs.mha --perfect-labels WORK/CASE_truth/labels.mha
                    --every K -o WORK/CASE.perfect.slices.json
  sonoshape reconstruct X.slices.json -o X_recon --depth D        (for both slice sets)
  sonoshape evaluate --recon X_recon --truth L:WORK/CASE_truth/label_L.ply ...
                     --slices X.slices.json --json X.eval.json
and prints one Markdown table: per case and label, each method's Dice over all frames (the
report's `total`) and scan IoU, the scan IoU with perfect labels (the truth label frames through
the same contour and placement code: the upper bound of the scan) and each method's gap to it. A label without a reconstructed mesh shows "no mesh" (and counts as IoU 0
in the gap). `--write-doc` puts the table into docs/benchmarks.md between
`<!-- segmentation_table:begin -->` and `<!-- segmentation_table:end -->`.

Phantoms: "default" (spot, cheburashka and a rib, as `simulate` makes it), "nested" (spot with a
copy of itself at 30 % inside it, written to WORK/phantoms/), "similar" (the default layout with
cheburashka as hypoechoic as spot). Noise levels are the tracker's: "low" (the simulator's default,
0.1 mm / 0.05 deg) and "high" (0.5 mm / 0.3 deg). The default set is quick (4 cases); `--full`
runs every phantom x probe x trajectory x noise level (48 cases). With `--seeds 1,2,3` every case
is simulated with each seed (in WORK/seedS/) and the table gives the means over the seeds and the
range of the last method's gap: one sweep's IoU moves by a few hundredths with the speckle and the
tracker noise of its seed, as much as the differences between labellings, so single-seed gaps
are not worth comparing at that level.
`--issue-baseline OLD/build/apps/sonoshape` adds, as the first labelling, the segmenter of
another build (the one the segmentation issue measured, ed734b2: `segment --every K` with its
defaults, before the graph cut, the bone sections, the blooming correction and the depth trend's
second start); its slices are reconstructed and scored by this build, so that only the labelling
differs. That build's `segment` cannot score its label maps, so its Dice columns show "–".
The exit status is non-zero when a command fails.

Usage: bench/segmentation_table.py [--binary build/apps/sonoshape] [--work out/bench/segmentation]
                                   [--full] [--only CASE ...] [--frames 200] [--every 4]
                                   [--depth 7] [--seeds 1,2,3] [--issue-baseline OLD_BINARY]
                                   [--write-doc]
"""
import argparse
import itertools
import json
import os
import platform
import re
import struct
import subprocess
import sys
import time

from doc_tables import write_between_markers

PROBES = ["convex", "linear"]
TRAJECTORIES = ["sweep", "fan", "rock", "rotate"]
NOISE = {"low": [], "high": ["--position-noise-mm", "0.5", "--angle-noise-deg", "0.3"]}
# The labellings compared, as `segment` options: the baseline first, then the graph cut on the
# image alone and with the reconstruction of the slices so far as its prior.
METHODS = {"threshold": ["--method", "threshold"],
           "graph cut": ["--method", "graph-cut", "--prior", "none"],
           "graph cut + prior": ["--method", "graph-cut", "--prior", "reconstruction"]}
QUICK = [("default", "convex", "sweep", "low"), ("default", "linear", "sweep", "low"),
         ("nested", "convex", "sweep", "low"), ("similar", "convex", "sweep", "low")]

# The inner organ of the nested phantom: spot scaled by 0.3 about its box centre and moved by this
# much (spot's own units; its box is about 0.94 x 1.69 x 1.72) into the torso (checked: every
# vertex of the copy lies inside spot).
NESTED_SCALE = 0.3
NESTED_SHIFT = (0.0, 0.05, -0.15)


def write_scaled_obj(src, dst, scale, shift):
    """Copies the .obj `src` to `dst` with its vertices scaled about the box centre and shifted
    (in the mesh's own units); faces and everything else are kept as written."""
    with open(src) as f:
        lines = f.read().splitlines()
    vertices = [[float(x) for x in line.split()[1:4]] for line in lines if line.startswith("v ")]
    lo = [min(v[i] for v in vertices) for i in range(3)]
    hi = [max(v[i] for v in vertices) for i in range(3)]
    centre = [0.5 * (lo[i] + hi[i]) for i in range(3)]
    out = []
    for line in lines:
        if line.startswith("v "):
            v = [float(x) for x in line.split()[1:4]]
            line = "v " + " ".join(f"{centre[i] + shift[i] + scale * (v[i] - centre[i]):.6f}"
                                   for i in range(3))
        out.append(line)
    with open(dst, "w") as f:
        f.write("\n".join(out) + "\n")


def phantom_args(root, work, phantom):
    if phantom == "default":
        return []
    if phantom == "similar":
        return ["--tissue", "1:hypoechoic", "--tissue", "2:hypoechoic"]
    spot = os.path.join(root, "data", "models", "spot.obj")
    inner = os.path.join(work, "phantoms", "spot_inner.obj")
    os.makedirs(os.path.dirname(inner), exist_ok=True)
    write_scaled_obj(spot, inner, NESTED_SCALE, NESTED_SHIFT)
    return ["--phantom", f"1:{spot}:spot", "--phantom", f"2:{inner}:inner",
            "--tissue", "1:hypoechoic", "--tissue", "2:hyperechoic"]


def case_name(case):
    return "_".join(case)


def header_field(sweep, key):
    """The value of `key = ...` in the sequence header `simulate` writes, or "" without one."""
    with open(sweep, "rb") as f:
        header = f.read(65536).split(b"ElementDataFile", 1)[0].decode("latin-1")
    m = re.search(rf"^{key} = (.*)$", header, re.MULTILINE)
    return m.group(1) if m else ""


def header_label_names(sweep):
    """{label: name} from the `SonoshapeLabels = 1:spot 2:...` line (the names of labels that no
    frame shows are nowhere else)."""
    pairs = (item.split(":", 1) for item in header_field(sweep, "SonoshapeLabels").split())
    return {int(label): name for label, name in pairs}


def header_models(sweep):
    """The labels with a grey model in the sequence header (`SonoshapeLabelGreyMean`)."""
    return {int(item.split(":", 1)[0])
            for item in header_field(sweep, "SonoshapeLabelGreyMean").split()}


def vertex_centroid(ply):
    """The mean of a binary little-endian PLY's float x y z vertices (as `simulate` writes)."""
    with open(ply, "rb") as f:
        data = f.read()
    header, _, body = data.partition(b"end_header\n")
    count = next(int(line.split()[2]) for line in header.decode("latin-1").splitlines()
                 if line.startswith("element vertex"))
    xyz = struct.unpack_from(f"<{3 * count}f", body)
    return [sum(xyz[i::3]) / count for i in range(3)]


def seed_args(sweep, truth_meshes):
    """`--organ-seed L:X,Y,Z` for every organ with a grey model: its truth mesh's vertex centroid,
    standing in for the clinician's one click on each organ that tells look-alikes apart."""
    models = header_models(sweep)
    return [arg for label, path in truth_meshes if label in models
            for arg in ("--organ-seed", f"{label}:" + ",".join(f"{c:.2f}" for c in vertex_centroid(path)))]


def run(cmd, what):
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        lines = result.stderr.strip().splitlines()
        raise RuntimeError(f"{what} failed: {lines[-1] if lines else result.returncode}")
    return result


def scan_scores(args, base, slices, truth_meshes):
    """Reconstructs `slices` into BASE_recon and scores it: {label: eval entry}."""
    recon, eval_path = base + "_recon", base + ".eval.json"
    cmd = [args.binary, "reconstruct", "--field", "mean-value", slices, "-o", recon, "-q"]
    if args.depth:
        cmd += ["--depth", str(args.depth)]
    run(cmd, f"reconstruct {slices}")
    truths = [t for label, path in truth_meshes for t in ("--truth", f"{label}:{path}")]
    run([args.binary, "evaluate", "--recon", recon, *truths, "--slices", slices,
         "--json", eval_path, "-q"], f"evaluate {recon}")
    with open(eval_path) as f:
        return {entry["label"]: entry for entry in json.load(f)["labels"]}


def one_case(args, root, case):
    phantom, probe, trajectory, noise = case
    base = os.path.join(args.work, case_name(case))
    truth = base + "_truth"
    run([args.binary, "simulate", *phantom_args(root, args.work, phantom), "--probe", probe,
         "--trajectory", trajectory, *NOISE[noise], "--frames", str(args.frames),
         "--seed", str(args.seed), "-o", base + ".igs.mha", "--truth", truth], "simulate")
    labels_mha = os.path.join(truth, "labels.mha")
    truth_meshes = sorted((int(m.group(1)), os.path.join(truth, name))
                          for name in os.listdir(truth)
                          if (m := re.fullmatch(r"label_(\d+)\.ply", name)))
    totals, scans = {}, {}
    seeds = seed_args(base + ".igs.mha", truth_meshes)
    if args.issue_baseline:
        out = f"{base}.issue_baseline"
        run([args.issue_baseline, "segment", base + ".igs.mha", "--every", str(args.every),
             "-o", out + ".slices.json"], f"segment ({args.baseline_name})")
        scans[args.baseline_name] = scan_scores(args, out, out + ".slices.json", truth_meshes)
    for method, options in METHODS.items():
        out = f"{base}.{method.replace(' ', '').replace('+', '_')}"
        if "graph-cut" in options:
            options = options + seeds
        run([args.binary, "segment", base + ".igs.mha", *options, "--truth-labels",
             labels_mha, "--report", out + ".seg.json", "--every", str(args.every),
             "-o", out + ".slices.json"], f"segment {' '.join(options)}")
        with open(out + ".seg.json") as f:
            totals[method] = json.load(f)["total"]
        scans[method] = scan_scores(args, out, out + ".slices.json", truth_meshes)
    run([args.binary, "segment", base + ".igs.mha", "--perfect-labels", labels_mha,
         "--every", str(args.every), "-o", base + ".perfect.slices.json"], "segment (perfect)")
    perfect = scan_scores(args, base + ".perfect", base + ".perfect.slices.json", truth_meshes)
    names = header_label_names(base + ".igs.mha")
    rows = []
    for label, _ in truth_meshes:
        row = {"case": case, "label": label, "perfect": perfect.get(label)}
        for method in METHODS:
            dice = totals[method]["labels"].get(str(label), {})
            row["name"] = dice.get("name") or names.get(label, f"label_{label}")
            row[method] = {"dice": dice.get("dice"), "scan": scans[method].get(label)}
        if args.issue_baseline:
            row[args.baseline_name] = {"dice": None, "scan": scans[args.baseline_name].get(label)}
        rows.append(row)
    return rows, totals[list(METHODS)[-1]]["unknown"]


def iou(entry):
    """The scan IoU, or None when the label has no reconstructed mesh."""
    if not entry or not entry.get("reconstructed") or entry.get("iou") is None:
        return None
    return entry["iou"]


def cell(value):
    return "no mesh" if value is None else f"{value:.3f}"


def mean(values):
    return sum(values) / len(values)


def table(rows, failures, seeds, baseline_name=None):
    """One line per case and label. With several seeds, `rows` holds one row per seed and label
    and every figure is the mean over the seeds (an IoU without a mesh counting as 0 where the
    perfect labels have one), with the range of the last method's gap beside it. With
    `baseline_name`, that labelling (another build's, without Dice) comes first."""
    methods = ([baseline_name] if baseline_name else []) + list(METHODS)
    several = len(seeds) > 1
    header = (["phantom", "probe", "trajectory", "noise", "label"] +
              [f"Dice {m}" for m in methods] + [f"IoU {m}" for m in methods] +
              ["IoU perfect labels"] + [f"gap {m}" for m in methods])
    if several:
        header.append(f"gap {methods[-1]}, range over seeds")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    groups = {}
    for r in rows:
        groups.setdefault((r["case"], r["label"]), []).append(r)
    for (case, label), group in groups.items():
        perfects = [iou(r["perfect"]) for r in group]
        has_perfect = all(p is not None for p in perfects)
        dices, scans, gaps, last_gaps = [], [], [], []
        for method in methods:
            # A label missing from the report is in no truth frame (nor in ours).
            dice = [r[method]["dice"] for r in group if r[method]["dice"] is not None]
            if method == baseline_name:
                dices.append("–")
            else:
                dices.append(f"{mean(dice):.3f}" if dice else "not in frames")
            ours = [iou(r[method]["scan"]) for r in group]
            if all(o is None for o in ours):
                scans.append("no mesh")
            else:
                scans.append(f"{mean([o or 0.0 for o in ours]):.3f}")
            if has_perfect:
                per_seed = [p - (o or 0.0) for p, o in zip(perfects, ours)]
                gaps.append(f"{mean(per_seed):.3f}")
                last_gaps = per_seed
            else:
                gaps.append("–")
        perfect = f"{mean(perfects):.3f}" if has_perfect else cell(None)
        extra = ""
        if several:
            extra = (f" | {min(last_gaps):.3f} – {max(last_gaps):.3f}" if last_gaps else " | –")
        lines.append(f"| {' | '.join(case)} | {label} {group[0]['name']} | "
                     f"{' | '.join(dices)} | {' | '.join(scans)} | {perfect} | "
                     f"{' | '.join(gaps)}{extra} |")
    for case, seed, error in failures:
        lines.append(f"| {' | '.join(case)} | FAILED (seed {seed}): {error} |" +
                     " |" * (len(header) - 5))
    return "\n".join(lines)


def commit_of(binary):
    """The commit of the checkout a sonoshape binary was built in."""
    folder = os.path.dirname(os.path.abspath(binary))
    return subprocess.run(["git", "-C", folder, "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip() or "unknown"


def provenance(args, seconds, cases, load_at_start):
    commit = commit_of(args.binary)
    baseline = (f" (the first labelling: `segment` of the build at {commit_of(args.issue_baseline)})"
                if args.issue_baseline else "")
    return (f"{len(cases)} cases, --frames {args.frames} --every {args.every} "
            f"--depth {args.depth or 'default'} --seeds {','.join(map(str, args.seeds))}"
            f"{' (figures: means over the seeds)' if len(args.seeds) > 1 else ''}; "
            f"sonoshape at commit {commit}{baseline}; "
            f"{os.cpu_count()} cores ({platform.machine()}, {platform.system()}), load average "
            f"{load_at_start:.1f} at the start and {os.getloadavg()[0]:.1f} at the end; "
            f"{seconds:.0f} s in all.")


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--work", default=os.path.join(root, "out", "bench", "segmentation"))
    parser.add_argument("--full", action="store_true",
                        help="every phantom x probe x trajectory x noise level (48 cases)")
    parser.add_argument("--only", nargs="*", help="case names (phantom_probe_trajectory_noise)")
    parser.add_argument("--frames", type=int, default=200, help="frames per simulated sweep")
    parser.add_argument("--every", type=int, default=4, help="segment every K-th frame")
    parser.add_argument("--depth", type=int, default=7, help="octree depth (0: the default)")
    parser.add_argument("--seeds", default="1",
                        help="simulator seeds, comma-separated; with several, the table gives "
                             "the means over them and the range of the last method's gap")
    parser.add_argument("--issue-baseline", default="",
                        help="another build's sonoshape whose segment is the first labelling "
                             "(the one the segmentation issue measured)")
    parser.add_argument("--write-doc", action="store_true",
                        help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    args.baseline_name = None
    if args.issue_baseline:
        args.baseline_name = f"at {commit_of(args.issue_baseline)}"

    os.makedirs(args.work, exist_ok=True)
    cases = (list(itertools.product(["default", "nested", "similar"], PROBES, TRAJECTORIES,
                                    list(NOISE))) if args.full else QUICK)
    if args.only:
        cases = [c for c in cases if case_name(c) in args.only]
        if not cases:
            raise SystemExit(f"no case named {' '.join(args.only)} (add --full for the grid?)")
    args.seeds = [int(x) for x in args.seeds.split(",")]
    rows, failures = [], []
    start, load_at_start = time.monotonic(), os.getloadavg()[0]
    work = args.work
    for case in cases:
        for seed in args.seeds:
            case_start = time.monotonic()
            args.seed = seed
            args.work = work if len(args.seeds) == 1 else os.path.join(work, f"seed{seed}")
            os.makedirs(args.work, exist_ok=True)
            try:
                case_rows, unknown = one_case(args, root, case)
                rows += case_rows
                print(f"{case_name(case)} seed {seed}: {time.monotonic() - case_start:.1f} s "
                      f"(unknown area precision {unknown['precision']}, recall "
                      f"{unknown['recall']})", file=sys.stderr)
            except RuntimeError as e:
                failures.append((case, seed, str(e)))
                print(f"{case_name(case)} seed {seed}: {e}", file=sys.stderr)
    args.work = work
    text = table(rows, failures, args.seeds, args.baseline_name) + "\n\n" + provenance(args, time.monotonic() - start, cases, load_at_start)
    print(text)
    if args.write_doc:
        write_between_markers(root, "segmentation_table", text)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
