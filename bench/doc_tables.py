"""Writes a benchmark script's table into docs/benchmarks.md between its two markers."""
import datetime
import os
import platform
import subprocess


def write_between_markers(root, name, text):
    """Replaces what lies between `<!-- NAME:begin -->` and `<!-- NAME:end -->` with `text`."""
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    path = os.path.join(root, "docs", "benchmarks.md")
    with open(path) as f:
        doc = f.read()
    if begin not in doc or end not in doc:
        raise SystemExit(f"{path} has no {begin} ... {end} markers")
    head, rest = doc.split(begin, 1)
    _, tail = rest.split(end, 1)
    with open(path, "w") as f:
        f.write(head + begin + "\n" + text + "\n" + end + tail)


def provenance(root, load_at_start, seconds):
    """The line under a table: the commit measured, the date, the machine and its load during the
    run (`load_at_start`: os.getloadavg()[0] when the run began; `seconds`: its wall time)."""
    commit = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip() or "unknown"
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    return (f"sonoshape at commit {commit}, {date}; {os.cpu_count()} cores ({platform.machine()}, "
            f"{platform.system()}), load average {load_at_start:.1f} at the start and "
            f"{os.getloadavg()[0]:.1f} at the end; {seconds:.0f} s in all.")


if __name__ == "__main__":
    # For shell scripts: `... | python3 bench/doc_tables.py NAME LOAD_AT_START SECONDS` writes
    # stdin and the provenance line between NAME's markers.
    import sys
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    name, load, seconds = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    table = sys.stdin.read().rstrip("\n")
    write_between_markers(here, name, table + "\n\n" + provenance(here, load, seconds))
