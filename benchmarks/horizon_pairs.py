"""What integrating kinked pairs again costs and gains (issue 11: pairs across a horizon).

Run: python -m benchmarks.horizon_pairs [--tol 1e-3] [--rounds 2]   (prints markdown; not part of
the test suite: the reference solve at tol / 10 takes minutes)

The Cornell box of `benchmarks.scene_scaling` at about 1,000 patches (two spheres on the floor, a
NURBS shell, a ceiling lamp) is solved at `tol` with `PairCache.refine_kinks` switched off (every
pair keeps its fixed outer rule, as before commit 79cbc61) and on, in turn in one process; each
patch's radiosity is compared with a solve at tol / 10 with it on. Times are medians over the
rounds (the machine is shared: compare the two rows of one run only).
"""

import argparse
import statistics
import subprocess
import time
from pathlib import Path

import numpy as np

from benchmarks import scene_scaling
from core import scene as scene_module

ROOT = Path(__file__).resolve().parent.parent


def solve(tol, kinks):
    """Patch radiosities (red channel, all objects) and the solve's time and stats."""
    original = scene_module.PairCache.refine_kinks
    if not kinks:
        scene_module.PairCache.refine_kinks = lambda self, *args: 0
    try:
        scene, handles, _ = scene_scaling.build(1000)
        start = time.perf_counter()
        solution = scene.solve(tol=tol)
        seconds = time.perf_counter() - start
    finally:
        scene_module.PairCache.refine_kinks = original
    B = np.concatenate([solution.radiosity(h)[:, 0] for h in handles])
    return B, seconds, solution.stats


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tol", type=float, default=1e-3)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    reference, ref_seconds, _ = solve(args.tol / 10, True)
    rows = {False: [], True: []}
    for _ in range(args.rounds):
        for kinks in (False, True):
            rows[kinks].append(solve(args.tol, kinks))
    head = f"Cornell box, {reference.size} patches, tol {args.tol:g}, commit {commit.stdout.strip()}"
    print(f"{head}; reference: the same scene at tol {args.tol / 10:g} with kinked pairs integrated")
    print(f"again ({ref_seconds:.0f} s).\n")
    print("| kinked pairs | solve (s) | of which kinked form factors (s) | pairs integrated again |")
    print("| --- | --- | --- | --- |")
    errors = {}
    for kinks in (False, True):
        B, _, stats = rows[kinks][-1]
        seconds = statistics.median(r[1] for r in rows[kinks])
        kinked = statistics.median(r[2]["times"].get("kinked form factors", 0.0) for r in rows[kinks])
        label = "integrated again" if kinks else "fixed rule (before)"
        print(f"| {label} | {seconds:.1f} | {kinked:.1f} | {stats.get('pairs_kinked', 0)} |")
        errors[kinks] = np.abs(B / reference - 1)
    print("\n| kinked pairs | max rel. error per patch | rms | p99 |")
    print("| --- | --- | --- | --- |")
    for kinks in (False, True):
        e = errors[kinks]
        label = "integrated again" if kinks else "fixed rule (before)"
        print(f"| {label} | {e.max():.2e} | {np.sqrt(np.mean(e**2)):.2e} | {np.quantile(e, 0.99):.2e} |")


if __name__ == "__main__":
    main()
