"""Does the hierarchical result settle as tol falls? The Cornell scene of `scene_scaling` (issues 13 / 11).

Solves the ~N-patch Cornell box (two spheres, one resting on the floor, a lamp quad under the
ceiling, optionally the floating NURBS shell) hierarchically at tol and at tol / --ratio, and all
pairs at tol, and prints per object the largest and mean |B - B_ref| / max B_ref (channel-wise
largest) against the tighter hierarchical solve, with the signed mean, and each solve's time and
link count. The tighter solve is a reference of the same method, not an independent one: what
this shows is whether tol's promise holds between tols (a plateau or a scatter far above tol
points at an error the link estimates do not count), not the absolute error. All pairs is shown
for its time and for how far its patch means lie from the hierarchy's at resting contacts (they
are means over different discretisations: see BENCHMARKS.md, "The hierarchy against all pairs at
a resting ball").

Run: python -m benchmarks.hierarchy_consistency [--patches 250] [--tol 1e-3] [--ratio 3.33]
                                                [--no-nurbs]
"""

import argparse
import time

import numpy as np

from . import scene_scaling


def solve(patches, tol, method):
    """(radiosity per patch (N, 3), object of each patch (N,), seconds, links)."""
    scene, handles, grids = scene_scaling.build(patches)
    start = time.perf_counter()
    solution = scene.solve(tol=tol, method=method, threads=2)
    seconds = time.perf_counter() - start
    B = np.concatenate([solution.radiosity(h) for h in handles])
    owner = np.repeat(np.arange(len(grids)), [nu * nv for nu, nv in grids])
    return B, owner, seconds, solution.stats.get("links")


def compare(B, reference, owner, log):
    """Per object: max and mean of |B - reference| / max(reference) per patch, signed mean."""
    scale = np.maximum(reference.max(1), 1e-300)
    off = np.abs(B - reference).max(1) / scale
    signed = (B - reference).sum(1) / np.maximum(reference.sum(1), 1e-300)
    for k in np.unique(owner):
        m = owner == k
        log(
            f"    object {k}: patches {m.sum():4d}  max {off[m].max():.2e}  mean {off[m].mean():.2e}"
            f"  signed mean {signed[m].mean():+.2e}"
        )
    log(f"    all: max {off.max():.2e}  p90 {np.quantile(off, 0.9):.2e}  mean {off.mean():.2e}")


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--patches", type=int, default=250)
    parser.add_argument("--tol", type=float, default=1e-3)
    parser.add_argument("--ratio", type=float, default=3.33)
    parser.add_argument("--no-nurbs", action="store_true")
    args = parser.parse_args(argv)
    scene_scaling.WITH_NURBS[0] = not args.no_nurbs
    tight = args.tol / args.ratio
    reference, owner, seconds, links = solve(args.patches, tight, "hierarchical")
    print(f"hierarchical tol {tight:.3g}: {seconds:.1f} s, {links} links (the reference)", flush=True)
    for method in ("hierarchical", "pairs"):
        B, _, seconds, links = solve(args.patches, args.tol, method)
        print(f"{method} tol {args.tol:g}: {seconds:.1f} s, {links} links; against the reference:")
        compare(B, reference, owner, print)


if __name__ == "__main__":
    main()
