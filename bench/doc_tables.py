"""Writes a benchmark script's table into docs/benchmarks.md between its two markers."""
import os


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
