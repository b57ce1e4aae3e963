#!/usr/bin/env python3
"""mitsuba_render.py: the Mitsuba 3 peer of bench/bench_render.cpp.

Loads a scene with Mitsuba 3, renders it once untimed (JIT compilation of the
llvm variants, first touch of the scene), then --repeat times timed, and prints
one JSON line on stdout:

  {"ok": true, "variant": ..., "mitsuba": ..., "times_s": [...], "load_s": ...,
   "warmup_s": ..., "width": ..., "height": ..., "spp": ..., "threads": ...,
   "removed_properties": [...], "mean": ...}
or {"ok": false, "error": "...", "tried": [...]}.

Timed: mi.render(scene, spp=N, seed=0) up to the developed film as a NumPy array
(so the lazily evaluated llvm render has run to completion) and dr.sync_thread().
Not timed: Python start-up, scene load and the warm-up render (for llvm_ad_rgb,
kernel compilation; later renders of the same spp hit Dr.Jit's kernel cache).

Mitsuba 0.5 scenes are upgraded by Mitsuba 3's loader, but it rejects properties
it does not know ("unreferenced property"). Such properties are removed from a
temporary copy of the scene (with the scene's folder on Mitsuba's file
resolver, so relative paths resolve) one by one and reported in "removed_properties"; any other load error is fatal.

--variant auto tries llvm_ad_rgb, then scalar_rgb, each in a child process (an
LLVM failure aborts the whole process, so it cannot be caught in-process).

Versions: on Debian 12 (libLLVM 14 and 15) use mitsuba==3.6.4 (drjit 1.0.5).
Mitsuba 3.9.1 (drjit 1.5) emits llvm.minimum/maximum, which LLVM 15 and 16 cannot
select on x86 ("LLVM ERROR: Cannot select: fminimum"), and Dr.Jit needs LLVM >= 15.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time


def emit(obj):
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def nan_mean(dr, a, np):
    """The mean of the finite-or-infinite entries, NaNs left out (numpy's nanmean, or Dr.Jit's reduction)."""
    if np is not None:
        return float(np.nanmean(a))
    x = a.array
    ok = ~dr.isnan(x)
    return float(dr.sum(dr.select(ok, x, 0))[0] / max(1.0, dr.sum(dr.select(ok, 1.0, 0.0))[0]))


def render(args):
    import mitsuba as mi

    mi.set_variant(args.variant)
    import drjit as dr

    try:  # numpy only copies the image out; without it Dr.Jit evaluates and reduces the tensor itself
        import numpy as np
    except ImportError:
        np = None

    if args.threads > 0:
        dr.set_thread_count(args.threads)
    path = os.path.abspath(args.scene)
    folder = os.path.dirname(path)
    src = open(path, encoding="utf-8").read()
    original = src
    # --width/--height: the film's integers, in a temporary copy of the scene.
    for name, value in (("width", args.width), ("height", args.height)):
        if value > 0:
            film = re.search(r"<film\b.*?</film>", src, re.S)
            if not film:
                raise RuntimeError("no <film> to set the %s of" % name)
            block, n = re.subn(r'(<integer\s+name="%s"\s+value=")[^"]*(")' % name, r"\g<1>%d\g<2>" % value, film.group(0))
            if n != 1:
                raise RuntimeError("the film has no single %s to set" % name)
            src = src[: film.start()] + block + src[film.end():]
    mi.Thread.thread().file_resolver().prepend(folder)
    removed = []
    t0 = time.perf_counter()
    scene = None
    tmp = None
    try:
        for _ in range(32):
            try:
                if src != original:
                    fd, tmp = tempfile.mkstemp(suffix=".xml", prefix="mitsuba3-")
                    with os.fdopen(fd, "w", encoding="utf-8") as f:
                        f.write(src)
                    scene = mi.load_file(tmp)
                else:
                    scene = mi.load_file(path)
                break
            except Exception as e:  # noqa: BLE001 - Mitsuba raises RuntimeError/ValueError
                m = re.search(r'unreferenced property "\[?"?([A-Za-z_0-9]+)', str(e))
                if not m:
                    raise
                name = m.group(1)
                new = re.sub(r'<[^<>]*name="%s"[^<>]*/>' % re.escape(name), "", src)
                if new == src:
                    raise
                src = new
                removed.append(name)
                if tmp:
                    os.unlink(tmp)
                    tmp = None
    finally:
        if tmp and os.path.exists(tmp):
            os.unlink(tmp)
    if scene is None:
        raise RuntimeError("scene did not load after removing %s" % removed)
    load_s = time.perf_counter() - t0

    def once():
        t = time.perf_counter()
        img = mi.render(scene, spp=args.spp, seed=0)
        if np is not None:
            a = np.array(img)
        else:
            a = img[:, :, 0:3]
            dr.eval(a)
        dr.sync_thread()
        return time.perf_counter() - t, a

    warmup_s, a = once()
    times = []
    for _ in range(args.repeat):
        s, a = once()
        times.append(s)
    film = scene.sensors()[0].film()
    size = film.crop_size()
    integrator = " ".join(str(scene.integrator()).split())  # e.g. PathIntegrator[ max_depth = 8, rr_depth = 5 ]
    out = {
        "ok": True,
        "variant": args.variant,
        "mitsuba": mi.__version__,
        "drjit": dr.__version__,
        "times_s": times,
        "load_s": load_s,
        "warmup_s": warmup_s,
        "width": int(size[0]),
        "height": int(size[1]),
        "spp": args.spp,
        "threads": dr.thread_count(),
        "integrator": integrator,
        "removed_properties": removed,
        "mean": nan_mean(dr, a[..., :3] if np is not None else a, np),
    }
    if args.exr:
        mi.util.write_bitmap(args.exr, a[..., :3] if np is not None else a)
    emit(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3, help="timed renders after the warm-up")
    ap.add_argument("--threads", type=int, default=0, help="Dr.Jit worker threads (0: all cores)")
    ap.add_argument("--variant", default="auto", help="auto: llvm_ad_rgb, else scalar_rgb")
    ap.add_argument("--exr", default="", help="write the last render here")
    ap.add_argument("--width", type=int, default=0, help="film width (0: the scene's)")
    ap.add_argument("--height", type=int, default=0, help="film height (0: the scene's)")
    ap.add_argument("--timeout", type=float, default=1800, help="per variant, with --variant auto")
    args = ap.parse_args()

    if args.variant != "auto":
        try:
            render(args)
        except Exception as e:  # noqa: BLE001 - reported to the benchmark
            emit({"ok": False, "variant": args.variant, "error": "%s: %s" % (type(e).__name__, e)})
            return 1
        return 0

    try:
        import mitsuba  # noqa: F401
    except ImportError as e:
        emit({"ok": False, "error": "import mitsuba failed: %s" % e, "tried": []})
        return 1
    tried = []
    for variant in ("llvm_ad_rgb", "scalar_rgb"):
        cmd = [sys.executable, os.path.abspath(__file__), "--variant", variant, "--scene", args.scene,
               "--spp", str(args.spp), "--repeat", str(args.repeat), "--threads", str(args.threads),
               "--width", str(args.width), "--height", str(args.height)]
        if args.exr:
            cmd += ["--exr", args.exr]
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
        except subprocess.TimeoutExpired:
            tried.append({"variant": variant, "error": "timed out after %g s" % args.timeout})
            continue
        result = None
        for line in p.stdout.splitlines():
            # Mitsuba's log lines go to stdout too, ending in a colour reset
            # (ESC [0m) that then starts the next line: find the object.
            start = line.find('{"ok"')
            if start >= 0:
                try:
                    result = json.loads(line[start:])
                except ValueError:
                    pass
        if result and result.get("ok"):
            result["tried"] = tried
            emit(result)
            return 0
        err = (result or {}).get("error") or ("exit %d: %s" % (p.returncode, p.stderr.strip()[:400]))
        tried.append({"variant": variant, "error": err})
    emit({"ok": False, "error": "no Mitsuba variant could render the scene", "tried": tried})
    return 1


if __name__ == "__main__":
    sys.exit(main())
