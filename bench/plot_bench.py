#!/usr/bin/env python3
"""Plots `ocsimp bench` results and regenerates the results section of bench/README.md.

    plot_bench.py --results bench/results --readme bench/README.md [--mode full|quick] [--command TEXT]

Reads every RESULTS/*.json written by `ocsimp bench --json` (one per mesh) and the Markdown table beside each
(RESULTS/<name>.md, the command's stdout), then writes
  RESULTS/error.png  RMS distance (% of the bounding-box diagonal, log) against faces reached, one panel per
                     mesh, one line per method;
  RESULTS/time.png   seconds of the simplification call against the input's faces (log-log), one line per
                     method (the median over each mesh's targets);
and replaces what lies between the README's "<!-- bench-results:begin -->" and "<!-- bench-results:end -->"
lines (the file is created with just that section when it does not exist). Uses matplotlib's Agg backend
(Debian: python3-matplotlib).
"""

import argparse
import datetime
import glob
import json
import os
import platform
import statistics
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
from matplotlib.ticker import NullFormatter  # noqa: E402

BEGIN = "<!-- bench-results:begin -->"
END = "<!-- bench-results:end -->"
# Fixed colours and markers per method, so every figure reads the same.
STYLE = {
    "grid-mean": ("#9e9e9e", "v"),
    "grid-quadric": ("#1f77b4", "s"),
    "octree": ("#2ca02c", "D"),
    "decimate": ("#d62728", "o"),
    "two-stage": ("#9467bd", "^"),
    "meshopt": ("#ff7f0e", "x"),
    "meshopt-sloppy": ("#8c564b", "+"),
}
BASELINE = "meshopt"  # the peer the ratio table divides by


def load(results_dir):
    runs = []
    for path in sorted(glob.glob(os.path.join(results_dir, "*.json"))):
        with open(path) as f:
            data = json.load(f)
        if not data.get("results"):
            continue
        name = os.path.splitext(os.path.basename(path))[0]
        table_path = os.path.join(results_dir, name + ".md")
        table = open(table_path).read().strip() if os.path.exists(table_path) else ""
        runs.append({"name": name, "settings": data.get("settings", {}), "rows": data["results"], "table": table})
    runs.sort(key=lambda run: run["rows"][0]["input_faces"])
    return runs


def methods_in(runs):
    seen = []
    for run in runs:
        for row in run["rows"]:
            if row["method"] not in seen:
                seen.append(row["method"])
    order = list(STYLE)
    return sorted(seen, key=lambda m: order.index(m) if m in order else len(order))


def rms_percent(row):
    d = row.get("distance")
    return d["rms_percent"] if d else None


def plot_error(runs, methods, path):
    cols = min(3, len(runs))
    rows = (len(runs) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.9 * rows), squeeze=False)
    for ax, run in zip(axes.flat, runs):
        for method in methods:
            points = sorted(
                (r["faces"], rms_percent(r))
                for r in run["rows"]
                if r["method"] == method and r["faces"] > 0 and rms_percent(r) and rms_percent(r) > 0
            )
            if not points:
                continue
            colour, marker = STYLE.get(method, ("black", "."))
            ax.plot([p[0] for p in points], [p[1] for p in points], color=colour, marker=marker,
                    markersize=4, linewidth=1.2, label=method)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{run['name']} ({run['rows'][0]['input_faces']:,} faces)", fontsize=9)
        ax.set_xlabel("faces", fontsize=8)
        ax.set_ylabel("RMS, % of diagonal", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="both", linewidth=0.3, alpha=0.5)
    spare = list(axes.flat)[len(runs):]
    for ax in spare:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if spare:  # the legend takes the first empty panel
        spare[0].legend(handles, labels, loc="center", fontsize=8, frameon=False)
        fig.tight_layout()
    else:
        fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8, frameon=False)
        fig.tight_layout(rect=(0, 0.12 / rows, 1, 1))
    fig.savefig(path, dpi=80)
    plt.close(fig)


def plot_time(runs, methods, path):
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for method in methods:
        points = []
        for run in runs:
            seconds = [r["seconds"] for r in run["rows"] if r["method"] == method]
            if seconds:
                points.append((run["rows"][0]["input_faces"], max(statistics.median(seconds), 1e-6)))
        if not points:
            continue
        points.sort()
        colour, marker = STYLE.get(method, ("black", "."))
        ax.plot([p[0] for p in points], [p[1] for p in points], color=colour, marker=marker, markersize=4,
                linewidth=1.2, label=method)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("input faces", fontsize=9)
    ax.set_ylabel("seconds (median over targets)", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="both", linewidth=0.3, alpha=0.5)
    ax.legend(fontsize=8, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def target_label(row):
    ratio = row.get("target_ratio") or 0
    return f"{100 * ratio:g} %" if ratio > 0 else f"{row['target_faces']:,}"


def ratio_table(runs, methods):
    """Time and RMS of each method divided by meshopt_simplify's on the same mesh and target, same run."""
    others = [m for m in methods if m != BASELINE]
    if BASELINE not in methods or not others:
        return ""
    lines = [
        "| mesh | target | " + " | ".join(others) + " |",
        "|---|---|" + "---:|" * len(others),
    ]
    for run in runs:
        targets = []
        for r in run["rows"]:
            if r["target_faces"] not in targets:
                targets.append(r["target_faces"])
        for target in targets:
            rows = {r["method"]: r for r in run["rows"] if r["target_faces"] == target}
            base = rows.get(BASELINE)
            if not base or not rms_percent(base) or base["seconds"] <= 0:
                continue
            cells = []
            for m in others:
                r = rows.get(m)
                if not r or not rms_percent(r):
                    cells.append("-")
                    continue
                cells.append(f"{r['seconds'] / base['seconds']:.2g}× / {rms_percent(r) / rms_percent(base):.2f}×")
            lines.append(f"| {run['name']} | {target_label(base)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def machine():
    model = ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{model or platform.processor() or 'unknown CPU'}, {os.cpu_count()} logical cores"


def section(runs, methods, mode, command):
    s = runs[0]["settings"]
    meshopt = s.get("meshoptimizer_version")
    # MESHOPTIMIZER_VERSION is major * 1000 + minor * 10 (0.18 is 180).
    meshopt_text = f"meshoptimizer {meshopt // 1000}.{meshopt % 1000 // 10}" if meshopt else "meshoptimizer not built in"
    out = [
        BEGIN,
        "",
        f"Generated by `{command}` on {datetime.date.today().isoformat()} ({mode} mode): {machine()}; "
        f"median of {s.get('repeat')} run(s) per cell, ocsimp's methods on {s.get('threads')} thread(s), "
        f"{s.get('samples'):,} area samples each way for the distances, {meshopt_text}.",
        "",
        "![RMS error against faces](results/error.png)",
        "",
        "![time against input size](results/time.png)",
        "",
    ]
    ratios = ratio_table(runs, methods)
    if ratios:
        out += [
            "### Against meshopt_simplify, same run",
            "",
            "Each cell: time ratio / RMS ratio, the method's over meshopt_simplify's at the same target "
            "(below 1 is faster / closer).",
            "",
            ratios,
            "",
        ]
    out += ["### All numbers", ""]
    for run in runs:
        out += [f"#### {run['name']}", "", run["table"], ""]
    out += [
        "Machine-readable: `results/<mesh>.json` and `results/<mesh>.csv` (every distance both ways, every run's "
        "time).",
        "",
        END,
    ]
    return "\n".join(out)


def update_readme(path, text):
    old = open(path).read() if os.path.exists(path) else ""
    if BEGIN in old and END in old:
        head = old[: old.index(BEGIN)]
        tail = old[old.index(END) + len(END):]
        new = head + text + tail
    else:
        new = (old.rstrip() + "\n\n" if old else "# Benchmarks\n\n") + text + "\n"
    with open(path, "w") as f:
        f.write(new)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", required=True, help="folder of ocsimp bench --json files")
    parser.add_argument("--readme", required=True, help="README whose results section to regenerate")
    parser.add_argument("--mode", default="full", help="label for the README (full, quick)")
    parser.add_argument("--command", default="bench/run_bench.sh", help="the command to credit in the README")
    args = parser.parse_args()

    runs = load(args.results)
    if not runs:
        sys.exit(f"plot_bench.py: no results in {args.results}")
    methods = methods_in(runs)
    plot_error(runs, methods, os.path.join(args.results, "error.png"))
    plot_time(runs, methods, os.path.join(args.results, "time.png"))
    update_readme(args.readme, section(runs, methods, args.mode, args.command))
    for name in ("error.png", "time.png"):
        size = os.path.getsize(os.path.join(args.results, name))
        print(f"plot_bench.py: {os.path.join(args.results, name)} ({size // 1024} KB)")
    print(f"plot_bench.py: regenerated {args.readme}")


if __name__ == "__main__":
    main()
