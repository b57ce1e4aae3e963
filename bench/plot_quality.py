#!/usr/bin/env python3
"""plot_quality.py: the convergence plot of bench_quality (relMSE against wall
or CPU time, log-log, one line per method, one PNG per scene) from its Google Benchmark
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
    ap.add_argument("--time", choices=("wall", "cpu"), default="wall",
                    help="x axis: wall time (fastest repeat) or the process's CPU time")
    ap.add_argument("--suffix", default="", help="appended to the PNG names")
    args = ap.parse_args()
    data = json.load(open(args.json))
    curves = collections.defaultdict(lambda: collections.defaultdict(list))
    equal = collections.defaultdict(list)
    for b in data["benchmarks"]:
        m = re.match(r"quality/([^/]+)/([^/]+)/spp:(\d+)(/|$)", b["name"])
        if m and "relMSE" in b:
            t = b.get("cpu_seconds") if args.time == "cpu" else b.get("min_seconds", b["seconds"])
            curves[m.group(1)][m.group(2)].append((t, b["relMSE"], int(m.group(3))))
        m = re.match(r"equal_time/([^/]+)/spp:(\d+)(/|$)", b["name"])
        if m and "pt_relMSE" in b:
            equal[m.group(1)].append(b)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    os.makedirs(args.out, exist_ok=True)
    labels = {"pt": "path tracing", "psf": "path space filtering", "psf2": "path space filtering, 2 iterations",
              "psf4": "path space filtering, 4 iterations", "psf8": "path space filtering, 8 iterations"}
    order = ["pt", "psf", "psf2", "psf4", "psf8"]  # then bench_quality --method's, by name
    ctx = data.get("context", {})
    for scene, methods in curves.items():
        fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
        for name in order + sorted(set(methods) - set(order)):
            pts = sorted(methods.get(name, []))
            if not pts:
                continue
            # A --method's options are in the context block (method_NAME).
            extra = ctx.get("method_" + name)
            label = labels.get(name, "%s: %s" % (name, extra) if extra else name)
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", ms=3, label=label)
            for t, e, spp in pts:
                if name == "pt" and spp in (1, 4, 16, 64, 256, 1024):
                    ax.annotate("%d spp" % spp, (t, e), textcoords="offset points", xytext=(4, 4), fontsize=7)
        ax.set_xlabel("wall time of the render (s)" if args.time == "wall" else "CPU time of the render (s)")
        ax.set_ylabel("relMSE")
        ax.set_title("%s: relMSE against %s time\n(%s compute units, %s)" % (
            scene, args.time, ctx.get("psf_compute_units", "?"), ctx.get("psf_device", "").split(" / ")[-1]),
            fontsize=9)
        ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        path = os.path.join(args.out, "quality-convergence-%s%s.png" % (scene, args.suffix))
        fig.savefig(path)
        print("wrote", path)

    for scene, rows in equal.items():
        names = sorted({k[: -len("_relMSE")] for b in rows for k in b if k.endswith("_relMSE")} - {"pt"})
        names = [m for m in order[1:] if m in names] + [m for m in names if m not in order]
        methods = [m for m in names if all(m + "_relMSE" in b for b in rows)]
        print("\n%s\n" % scene)
        print("| plain spp | time | plain relMSE | " + " | ".join("%s (spp) | gain" % m for m in methods) + " |")
        print("| ---: | ---: | ---: | " + " | ".join("---: | ---:" for _ in methods) + " |")
        for b in sorted(rows, key=lambda b: b["pt_spp"]):
            cells = ["%d" % b["pt_spp"], "%.3g s" % b["pt_seconds"], "%.3g" % b["pt_relMSE"]]
            for m in methods:
                cells += ["%.3g (%d)" % (b[m + "_relMSE"], b[m + "_spp"]), "%.2f×" % b[m + "_gain"]]
            print("| " + " | ".join(cells) + " |")

if __name__ == "__main__":
    main()
