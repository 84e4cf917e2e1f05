#!/usr/bin/env python3
"""Appends the clean-observation entropy table to the paper_tables report, and its figures to the
run's results.json beside it (key "clean_entropy").

Reads OUT/<region>/<route>/single/poses.csv written by `seqloc localize --mode single` on routes
simulated with --clean, and prints (and appends to REPORT) per region: frames, mean normalized
entropy, median normalized entropy, single-frame R@5m.
usage: clean_entropy.py REPORT LOCALIZED_DIR REGION...
"""
import csv
import json
import pathlib
import sys


def main():
    report, localized, regions = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2]), sys.argv[3:]
    lines = [
        "",
        "## 9. Entropy of clean observations (no perception noise)",
        "",
        "Routes simulated with `--clean`: what the scenes alone leave ambiguous.",
        "",
        "| region | frames | mean entropy | median entropy | single-frame R@5m |",
        "|---|---:|---:|---:|---:|",
    ]
    figures = {}
    for region in regions:
        entropy, hits = [], 0
        for poses in sorted((localized / region).glob("*/single/poses.csv")):
            with open(poses, newline="") as f:
                for row in csv.DictReader(f):
                    entropy.append(float(row["entropy"]))
                    hits += float(row["position_error_m"]) < 5
        n = len(entropy)
        if n == 0:
            raise SystemExit(f"{localized / region}: no poses.csv found")
        median = sorted(entropy)[n // 2]
        lines.append(f"| {region} | {n} | {sum(entropy) / n:.3f} | {median:.3f} | {100 * hits / n:.1f} |")
        figures[region] = {"frames": n, "mean": sum(entropy) / n, "median": median, "single_r5m": 100 * hits / n}
    results_path = report.parent / "results.json"
    results = json.loads(results_path.read_text())
    results["clean_entropy"] = figures
    results_path.write_text(json.dumps(results, indent=2) + "\n")
    text = "\n".join(lines) + "\n"
    with open(report, "a") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
