"""Exact shadows' solve time against the core before them, in one run (issue 11's time goals).

Run: python -m benchmarks.shadow_time [--before REV] [--rounds N]   (prints markdown; not part of
the test suite)

The three scenes of `benchmarks.shadow_patches` (open cube, resting sphere, closed box) are solved
with the default occlusion at tol 1e-3 and 1e-4 by this checkout's core and by the core of git
revision REV (default d3438c3, where issue 11 was measured: visibility by rays alone), each in its
own process, the two in turn (A B A B ...) so that a drifting machine affects both alike. Every
process reports the best of three solves per case; the table gives the median over the rounds
and the ratios "now / before" and "tol 1e-4 / tol 1e-3" from those medians.
"""

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("open_cube", "resting_sphere", "closed_box")
TOLS = (1e-3, 1e-4)


def measure(core_root, repeats=3):
    """Best-of-`repeats` default solve time per (scene, tol) with the core found at core_root."""
    sys.path.insert(0, str(core_root))
    import core  # noqa: F401  (the one on core_root, which shadow_patches then uses)

    # the scenes from this checkout (an older one may not have them)
    spec = importlib.util.spec_from_file_location("shadow_patches", ROOT / "benchmarks" / "shadow_patches.py")
    shadow_patches = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(shadow_patches)

    out = {}
    for name in SCENES:
        _, build, _ = getattr(shadow_patches, name)()
        for tol in TOLS:
            best = np.inf
            for _ in range(repeats):
                scene, _ = build()
                start = time.perf_counter()
                scene.solve(tol=tol)
                best = min(best, time.perf_counter() - start)
            out[f"{name} {tol:.0e}"] = best
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="d3438c3")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    from .revisions import interleaved  # (here: the processes measured import this file alone)

    now, before, commit = interleaved(Path(__file__).resolve(), args.before, args.rounds)
    median = {k: float(np.median([r[k] for r in now])) for k in now[0]}
    median_before = {k: float(np.median([r[k] for r in before])) for k in now[0]}
    lines = [
        f"Default solve time, this checkout ({commit}) against {args.before}, "
        f"median of {args.rounds} interleaved processes (each the best of 3 solves):",
        "",
        "| scene | tol | before (s) | now (s) | now / before | now: tol 1e-4 / tol 1e-3 |",
        "|---|---|---|---|---|---|",
    ]
    for name in SCENES:
        for tol in TOLS:
            key = f"{name} {tol:.0e}"
            ratio = median[f"{name} 1e-04"] / median[f"{name} 1e-03"]
            lines.append(
                f"| {name} | {tol:.0e} | {median_before[key]:.3f} | {median[key]:.3f} | "
                f"{median[key] / median_before[key]:.2f} | {ratio:.2f} |"
            )
    print("\n".join(lines))
    return lines


if __name__ == "__main__":
    main()
