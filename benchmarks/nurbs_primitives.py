"""Blender's NURBS Surface primitives through the add-on, over the full flag and order grid.

Every case: a fresh empty scene, one primitive (`bpy.ops.surface.primitive_nurbs_surface_*`),
its spline's use_cyclic / use_endpoint / use_bezier in u and v (64 combinations) and order_u,
order_v in 2 .. 6 (Blender clamps an order to the point count, so the 4 x 4 Surface primitive
never goes past 4), 2 x 2 patches, one point light, solved through the installed extension's
pipeline at tol 1e-2 (as tests/blender/test_nurbs_mapping.py does for a subset). A case is
"solved" (finite values written), "refused" (a named PipelineError, e.g. Blender's own Bezier
rule), or a failure: "bad result", another exception, "timeout" (the case ran past --timeout
s: the child is killed and the run goes on with the next case) or "memory" (the child passed
--memory GB of address space: MemoryError).

    python -m benchmarks.nurbs_primitives [--kinds surface torus] [--orders 2 3 4 5 6]
        [--sample N] [--timeout 60] [--memory 4]

--sample N runs a seeded random N of the grid. Prints one line per case and a table per kind.
"""

import argparse
import itertools
import json
import os
import selectors
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
KINDS = ("surface", "sphere", "cylinder", "torus")
FLAGS = ("use_cyclic", "use_endpoint", "use_bezier")

CHILD = """
import importlib, json, os, resource, sys, tempfile, time, tracemalloc
import numpy as np
limit = int(float(sys.argv[3]) * 2**30)
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="curved-radiosity-grid-")
import bpy
zip_path, cases = sys.argv[1], json.load(open(sys.argv[2]))
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
addon = importlib.import_module("bl_ext.user_default.curved_radiosity")
print("READY", flush=True)
for case in cases:
    print("START " + json.dumps(case["id"]), flush=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    getattr(bpy.ops.surface, "primitive_nurbs_surface_%s_add" % case["kind"])()
    obj = bpy.context.active_object
    (spline,) = obj.data.splines
    for name, value in case["settings"].items():
        setattr(spline, name, value)
    obj.data.update_tag()
    obj.curved_radiosity_patches = (2, 2)
    bpy.ops.object.light_add(type="POINT", location=(0.3, 0.2, 4.0))
    bpy.context.active_object.data.energy = 200.0
    settings = addon.solve.Settings(tol=1e-2, occlusion=True, max_bounces=None)
    tracemalloc.start()
    start = time.perf_counter()
    try:
        addon.pipeline.compute(bpy.context, settings)
        twin = bpy.data.objects[obj.name + " radiosity"]
        values = addon.adapter.read_color_attribute(twin.data, "Radiosity")[:, :3]
        outcome = "solved" if values.size and np.isfinite(values).all() else "bad result"
    except addon.pipeline.PipelineError as error:
        outcome = "refused: %s" % error
    except MemoryError:
        outcome = "memory"
    except Exception as error:  # reported, not hidden
        outcome = "error: %r" % error
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print("CASE " + json.dumps(dict(case, outcome=outcome, seconds=seconds, peak=peak, rss=rss,
                                    orders=[spline.order_u, spline.order_v])), flush=True)
"""


def grid(kinds, orders):
    """Every (kind, flags in u, flags in v, order_u, order_v) case, each with an id."""
    cases = []
    for kind in kinds:
        for fu, fv, ou, ov in itertools.product(
            itertools.product([False, True], repeat=3),
            itertools.product([False, True], repeat=3),
            orders,
            orders,
        ):
            settings = {f"{f}_u": value for f, value in zip(FLAGS, fu)}
            settings.update({f"{f}_v": value for f, value in zip(FLAGS, fv)})
            settings.update(order_u=ou, order_v=ov)
            cases.append(dict(id=len(cases), kind=kind, settings=settings))
    return cases


def build_zip():
    out = tempfile.mkdtemp(prefix="curved-radiosity-dist-")
    command = [sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--output-dir", out]
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, check=True)
    return done.stdout.strip().splitlines()[-1]


def run(cases, zip_path, timeout, memory):
    """Run cases in child processes; a case past `timeout` s is recorded and its child killed."""
    records = {}
    todo = list(cases)
    while todo:
        listing = Path(tempfile.mkdtemp(prefix="curved-radiosity-cases-")) / "cases.json"
        listing.write_text(json.dumps(todo))
        child = subprocess.Popen(
            [sys.executable, "-c", CHILD, zip_path, str(listing), str(memory)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
        )
        current, started, pending = None, None, b""
        selector = selectors.DefaultSelector()
        selector.register(child.stdout, selectors.EVENT_READ)
        alive = True
        while alive:
            wait = 120.0 if current is None else max(0.0, started + timeout - time.perf_counter())
            if not selector.select(wait):
                break  # the current case ran out of time (or the start-up hung)
            # (raw reads: a buffered reader would hold lines that select() no longer reports)
            chunk = os.read(child.stdout.fileno(), 1 << 16)
            alive = bool(chunk)
            pending += chunk
            *lines, pending = pending.split(b"\n")
            for line in (raw.decode(errors="replace") for raw in lines):
                if line.startswith("START "):
                    current, started = json.loads(line[6:]), time.perf_counter()
                elif line.startswith("CASE "):
                    record = json.loads(line[5:])
                    records[record["id"]] = record
                    print_record(record)
                    current = None
        child.kill()
        child.wait()
        if current is not None and current not in records:
            case = next(c for c in todo if c["id"] == current)
            records[current] = dict(
                case,
                outcome="timeout" if child.returncode else "crashed",
                seconds=timeout,
                peak=None,
                rss=None,
                orders=None,
            )
            print_record(records[current])
        remaining = [c for c in todo if c["id"] not in records]
        if len(remaining) == len(todo):  # nothing progressed: give up on the first
            records[remaining[0]["id"]] = dict(
                remaining[0], outcome="crashed", seconds=None, peak=None, rss=None, orders=None
            )
            remaining = remaining[1:]
        todo = remaining
    return [records[c["id"]] for c in cases]


def print_record(r):
    flags = "".join("1" if r["settings"][f"{f}_{d}"] else "0" for d in "uv" for f in FLAGS)
    seconds = "-" if r["seconds"] is None else f"{r['seconds']:.2f}s"
    rss = "-" if r["rss"] is None else f"{r['rss'] / 1e6:.0f}MB"
    print(
        f"# {r['id']:4d} {r['kind']:<8s} flags(cyc,end,bez u;v)={flags} orders "
        f"{r['settings']['order_u']},{r['settings']['order_v']}->{r['orders']} {seconds} rss {rss} "
        f"{r['outcome']}",
        flush=True,
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    parser.add_argument("--orders", nargs="+", type=int, default=[2, 3, 4, 5, 6])
    parser.add_argument("--sample", type=int, default=None)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--memory", type=float, default=4.0, help="address-space limit of a child (GB)")
    args = parser.parse_args(argv)
    cases = grid(args.kinds, args.orders)
    if args.sample is not None and args.sample < len(cases):
        pick = np.sort(np.random.default_rng(args.seed).choice(len(cases), args.sample, replace=False))
        cases = [cases[k] for k in pick]
    records = run(cases, build_zip(), args.timeout, args.memory)
    print()
    print(f"{len(records)} cases, timeout {args.timeout:g} s, {args.memory:g} GB address space per child")
    print()
    print("| kind | cases | solved | refused (named) | failed | p50 (s) | max (s) | max RSS (MB) |")
    print("|---|---|---|---|---|---|---|---|")
    for kind in args.kinds:
        rows = [r for r in records if r["kind"] == kind]
        if not rows:
            continue
        solved = sum(r["outcome"] == "solved" for r in rows)
        refused = sum(r["outcome"].startswith("refused") for r in rows)
        seconds = np.array([r["seconds"] for r in rows if r["seconds"] is not None])
        rss = max((r["rss"] or 0) for r in rows)
        print(
            f"| {kind} | {len(rows)} | {solved} | {refused} | {len(rows) - solved - refused} | "
            f"{np.median(seconds):.2f} | {seconds.max():.2f} | {rss / 1e6:.0f} |"
        )
    reasons = {}
    for r in records:
        if r["outcome"] != "solved":
            key = r["outcome"].split(":")[0] + ": " + r["outcome"].split(":", 1)[-1][:90]
            reasons[key] = reasons.get(key, 0) + 1
    for key, count in sorted(reasons.items(), key=lambda kv: -kv[1]):
        print(f"- {count} x {key}")


if __name__ == "__main__":
    main()
