#!/usr/bin/env python3
"""plot_quality.py: the convergence plot of bench_quality (relMSE against wall
time, log-log, one line per method, one PNG per scene) from its Google Benchmark
JSON; also prints the equal-time table in Markdown.

Usage: plot_quality.py [bench/results/bench_quality.json] [--out docs/images]
Needs matplotlib (e.g. build/venv/bin/pip install matplotlib); not needed by the tests.
"""
import argparse
import collections
import json
import os
import re


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("json", nargs="?", default="bench/results/bench_quality.json")
    ap.add_argument("--out", default="docs/images")
    args = ap.parse_args()
    data = json.load(open(args.json))
    curves = collections.defaultdict(lambda: collections.defaultdict(list))
    equal = collections.defaultdict(list)
    for b in data["benchmarks"]:
        m = re.match(r"quality/([^/]+)/([^/]+)/spp:(\d+)$", b["name"])
        if m and "relMSE" in b:
            curves[m.group(1)][m.group(2)].append((b["seconds"], b["relMSE"], int(m.group(3))))
        m = re.match(r"equal_time/([^/]+)/spp:(\d+)$", b["name"])
        if m and "pt_relMSE" in b:
            equal[m.group(1)].append(b)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(args.out, exist_ok=True)
    labels = {"pt": "path tracing", "psf": "path space filtering", "psf2": "path space filtering, 2 iterations"}
    for scene, methods in curves.items():
        fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
        for name in ("pt", "psf", "psf2"):
            pts = sorted(methods.get(name, []))
            if not pts:
                continue
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", ms=3, label=labels[name])
            for t, e, spp in pts:
                if name == "pt" and spp in (1, 4, 16, 64, 256, 1024):
                    ax.annotate("%d spp" % spp, (t, e), textcoords="offset points", xytext=(4, 4), fontsize=7)
        ax.set_xlabel("wall time of the render (s)")
        ax.set_ylabel("relMSE")
        ax.set_title("%s: relMSE against time (%s)" % (scene, data.get("context", {}).get("psf_device", "")[-40:]),
                     fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        path = os.path.join(args.out, "quality_convergence_%s.png" % scene)
        fig.savefig(path)
        print("wrote", path)

    for scene, rows in equal.items():
        print("\n%s\n" % scene)
        print("| pt spp | time (s) | pt relMSE | psf spp | time (s) | psf relMSE | gain | psf2 spp | time (s) | "
              "psf2 relMSE | gain |")
        print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for b in sorted(rows, key=lambda b: b["pt_spp"]):
            print("| %d | %.3f | %.4g | %d | %.3f | %.4g | %.2fx | %d | %.3f | %.4g | %.2fx |" % (
                b["pt_spp"], b["pt_seconds"], b["pt_relMSE"], b["psf_spp"], b["psf_seconds"], b["psf_relMSE"],
                b["psf_gain"], b["psf2_spp"], b["psf2_seconds"], b["psf2_relMSE"], b["psf2_gain"]))


if __name__ == "__main__":
    main()
