#!/usr/bin/env python3
"""Tables and plot of a soak run (bench/soak.sh): memory, update time, latency and drops over time.

    python3 bench/soak_report.py DIR [--plot PNG] [--minutes M] [--warmup-min W]

DIR holds what bench/soak.sh wrote: rss.csv (the scan's RSS and CPU every 5 s), scan/scan.json,
fast/log.jsonl (every header the keeping-up subscriber got, with its arrival time), and the
subscribers' summary.json files. Writes DIR/soak.md and prints it. The RSS slope is a least-squares
line through the samples after the warm-up (default: the first third of the run, at least 5 min),
in MB per minute and as a share of the RSS at the end of the warm-up.
"""
import argparse
import json
import math
import pathlib
import statistics


def read_rss(path):
    rows = []
    for line in path.read_text().splitlines()[1:]:
        t, rss, cpu = line.split(",")
        rows.append((float(t), float(rss) / 1024.0, float(cpu) if cpu else math.nan))
    return rows


def slope(points):
    """Least-squares slope of (x, y) points."""
    n = len(points)
    if n < 2:
        return math.nan
    mx = sum(x for x, _ in points) / n
    my = sum(y for _, y in points) / n
    sxx = sum((x - mx) ** 2 for x, _ in points)
    return sum((x - mx) * (y - my) for x, y in points) / sxx if sxx > 0 else math.nan


def least_squares(rows, targets):
    """Coefficients x minimising |A x - b| for rows of A (normal equations, Gauss-Jordan)."""
    n = len(rows[0])
    m = [[sum(r[i] * r[j] for r in rows) for j in range(n)] +
         [sum(r[i] * t for r, t in zip(rows, targets))] for i in range(n)]
    for c in range(n):
        pivot = max(range(c, n), key=lambda r: abs(m[r][c]))
        m[c], m[pivot] = m[pivot], m[c]
        if abs(m[c][c]) < 1e-12:
            return [math.nan] * n
        for r in range(n):
            if r != c:
                f = m[r][c] / m[c][c]
                m[r] = [a - f * b for a, b in zip(m[r], m[c])]
    return [m[i][n] / m[i][i] for i in range(n)]


def slices_at(updates, t_s):
    """Slices the scan held at time t_s (the newest update before it)."""
    held = 0
    for u in updates:
        if u[0] > t_s:
            break
        held = u[1]
    return held


def percentile(values, q):
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q * (len(ordered) - 1))))]


def read_updates(log_path):
    """Live status messages that report an update: (received s, slices, update ms, latency ms)."""
    updates, seen = [], set()
    for line in log_path.read_text().splitlines():
        message = json.loads(line)
        if message.get("topic") != "status" or message.get("snapshot"):
            continue
        if "update_ms" not in message or "latency_ms" not in message:
            continue
        key = (message.get("slices"), message["update_ms"])
        if key in seen:  # a status repeated without a new update
            continue
        seen.add(key)
        updates.append((message["received_s"], message.get("slices", 0), message["update_ms"],
                        message["latency_ms"]))
    return updates


def summary(path):
    return json.loads(path.read_text()) if path.exists() else {}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("dir")
    parser.add_argument("--plot", default="")
    parser.add_argument("--minutes", type=float, default=0.0)
    parser.add_argument("--warmup-min", type=float, default=-1.0)
    options = parser.parse_args()
    root = pathlib.Path(options.dir)

    rss = read_rss(root / "rss.csv")
    minutes = options.minutes or (rss[-1][0] / 60.0 if rss else 0.0)
    warmup_min = options.warmup_min if options.warmup_min >= 0 else max(5.0, minutes / 3.0)
    after = [(t / 60.0, mb) for t, mb, _ in rss if t / 60.0 >= warmup_min]
    rss_slope = slope(after)
    rss_at_warmup = after[0][1] if after else math.nan
    updates = read_updates(root / "fast" / "log.jsonl")
    scan = summary(root / "scan" / "scan.json")
    # Memory follows the slices the scan holds (each adds planes, cells and octree nodes); a leak
    # grows with time. RSS = a + b * slices + c * minutes over the samples after the warm-up
    # separates the two: c is the growth at a constant slice count.
    late = [(t, mb) for t, mb, _ in rss if t / 60.0 >= warmup_min]
    per_slice_mb, per_min_mb = math.nan, math.nan
    if len(late) >= 3 and updates:
        rows = [(1.0, float(slices_at(updates, t)), t / 60.0) for t, _ in late]
        if len(set(r[1] for r in rows)) >= 2:
            _, per_slice_mb, per_min_mb = least_squares(rows, [mb for _, mb in late])

    lines = [f"Soak of {minutes:.0f} min (bench/soak.sh {minutes:.0f}); warm-up {warmup_min:.0f} min.", ""]
    lines += ["| quantity | value |", "|---|---|"]
    if rss:
        lines.append(f"| RSS at the end of the warm-up / at the end | {rss_at_warmup:.0f} MB / "
                     f"{rss[-1][1]:.0f} MB (peak {max(mb for _, mb, _ in rss):.0f} MB) |")
        lines.append(f"| RSS slope after the warm-up (least squares) | {rss_slope:+.2f} MB/min "
                     f"({100.0 * rss_slope / rss_at_warmup:+.3f} % of the warm-up RSS per min) |")
        third_min = minutes * 2.0 / 3.0  # the last third starts here
        last = [(t / 60.0, mb) for t, mb, _ in rss if t / 60.0 >= third_min]
        slices_then = slices_at(updates, third_min * 60.0)
        slices_end = slices_at(updates, minutes * 60.0)
        lines.append(f"| RSS slope over the last third ({third_min:.0f}-{minutes:.0f} min; "
                     f"{slices_then} -> {slices_end} slices) | {slope(last):+.2f} MB/min |")
        if not math.isnan(per_min_mb):
            lines.append(f"| the same, slice count held constant (RSS = a + b slices + c min) | "
                         f"c = {per_min_mb:+.2f} MB/min; b = {per_slice_mb:.2f} MB per slice |")
        cpu = [c for _, _, c in rss if not math.isnan(c)]
        if len(cpu) >= 2:
            lines.append(f"| scan CPU time | {cpu[-1]:.0f} s in {rss[-1][0]:.0f} s "
                         f"({cpu[-1] / rss[-1][0]:.2f} cores on average) |")
    if scan:
        lines.append(f"| frames received / dropped | {scan.get('frames_received')} / "
                     f"{scan.get('frames_dropped')} |")
        dropped = {k: v for k, v in scan.get("dropped", {}).items() if v}
        lines.append("| drops by reason | " +
                     (", ".join(f"{k} {v}" for k, v in sorted(dropped.items())) or "none") + " |")
        lines.append(f"| slices / near-duplicate frames skipped | {scan.get('slices')} / "
                     f"{scan.get('keyframes_skipped')} |")
        lines.append(f"| updates / errors | {scan.get('updates')} / "
                     f"{len(scan.get('errors', []))} |")
    lines.append("")

    # Update time and latency per 5-minute window (the fast subscriber's view).
    window_min = 5.0
    lines += ["| minutes | slices at the end | updates | update ms median / p90 | "
              "latency ms median / p90 |", "|---|---|---|---|---|"]
    start = 0.0
    while start < minutes - 1e-9:
        end = start + window_min
        rows = [u for u in updates if start * 60.0 <= u[0] < end * 60.0]
        if rows:
            update_ms = [u[2] for u in rows]
            latency_ms = [u[3] for u in rows]
            lines.append(f"| {start:.0f}-{end:.0f} | {rows[-1][1]} | {len(rows)} | "
                         f"{statistics.median(update_ms):.0f} / {percentile(update_ms, 0.9):.0f} | "
                         f"{statistics.median(latency_ms):.0f} / {percentile(latency_ms, 0.9):.0f} |")
        else:
            lines.append(f"| {start:.0f}-{end:.0f} | - | 0 | - | - |")
        start = end
    lines.append("")

    # What each subscriber got.
    lines += ["| subscriber | runs | messages | seq gaps | missed | invalid | stopped by |",
              "|---|---|---|---|---|---|---|"]
    for name in ("fast", "slow"):
        s = summary(root / name / "summary.json")
        if s:
            lines.append(f"| {name} | 1 | {s['messages']} | {s['seq_gaps']} | {s['missed']} | "
                         f"{s['invalid']} | {s['stopped_by']} |")
        else:
            lines.append(f"| {name} | 1 | no summary.json | | | | |")
    restarts = sorted((root / "restart").glob("*/summary.json"))
    if restarts:
        runs = [json.loads(p.read_text()) for p in restarts]
        with_snapshot = sum(1 for r in runs if r.get("snapshot_seq") is not None)
        lines.append(f"| restart (joins with a snapshot: {with_snapshot} of {len(runs)}) | "
                     f"{len(runs)} | {sum(r['messages'] for r in runs)} | "
                     f"{sum(r['seq_gaps'] for r in runs)} | {sum(r['missed'] for r in runs)} | "
                     f"{sum(r['invalid'] for r in runs)} | "
                     f"{', '.join(sorted(set(r['stopped_by'] for r in runs)))} |")
    text = "\n".join(lines) + "\n"
    (root / "soak.md").write_text(text)
    print(text)

    if options.plot:
        try:
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
        except ImportError:
            print("soak_report: no matplotlib (Debian python3-matplotlib): plot skipped")
            return
        figure, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        axes[0].plot([t / 60 for t, _, _ in rss], [mb for _, mb, _ in rss], color="tab:blue")
        axes[0].axvline(warmup_min, color="grey", linestyle=":")
        axes[0].set_ylabel("scan RSS (MB)")
        axes[0].set_ylim(bottom=0)
        axes[1].plot([u[0] / 60 for u in updates], [u[2] for u in updates], ".", markersize=2,
                     label="update time")
        axes[1].plot([u[0] / 60 for u in updates], [u[3] for u in updates], ".", markersize=2,
                     label="frame-to-mesh latency")
        axes[1].set_ylabel("ms")
        axes[1].set_yscale("log")
        axes[1].legend(loc="upper left", markerscale=4)
        axes[2].plot([u[0] / 60 for u in updates], [u[1] for u in updates], color="tab:green")
        axes[2].set_ylabel("slices")
        axes[2].set_xlabel("minutes")
        axes[2].set_ylim(bottom=0)
        figure.suptitle(f"soak: {minutes:.0f} min real-time simulated scan, three subscribers")
        figure.tight_layout()
        pathlib.Path(options.plot).parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(options.plot, dpi=90)
        print(f"plot: {options.plot}")


if __name__ == "__main__":
    main()
