"""Occlusion queries' time per query against an earlier core, in one run.

Run: python -m benchmarks.occlusion_queries [--before REV] [--rounds N]   (prints markdown; not
part of the test suite)

Three queries every occluded solve and gather makes, on fixed synthetic inputs:
- a NURBS proxy's segment test (`occlusion._Proxy.blocked`): the Cornell benchmark's shell
  (`scene_scaling.nurbs_shell`), 300,000 segments between random points on the faces of a box
  0.3 m around it;
- `bvh.BVH.segments_blocked`: a 64 x 32 UV ball's 4,096 triangles over a 40 x 40 floor's
  3,200, 300,000 random segments around them;
- `bvh.BVH.shaft_candidates`: 20,000 shafts (capsules between random points, 0.05-0.5 m) among
  5,000 balls (0.1-0.3 m) in a 10 m cube;
- `occlusion.Occluders.blocked` on exact kinds: 400,000 segments from random points of a 10 m
  cube aimed through one of 144 whole spheres (0.2-0.5 m) each, as example 05's rays run.
This checkout's core and the core of git revision REV (default a189b0a) run in turn, each in its
own process (A B A B ...), so a drifting machine affects both alike; each process reports the
best of 3 calls per query, the table the median over the rounds. Both must give the same
answers (checked: a hash of each result).
"""

import argparse
import hashlib
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
QUERIES = ("proxy segments", "BVH segments", "BVH shafts", "ball segments")
COUNTS = {"proxy segments": 300_000, "BVH segments": 300_000, "BVH shafts": 20_000, "ball segments": 400_000}


def _grid_triangles(V):
    """Two triangles per cell of a vertex grid V (a, b, 3), shape (2 (a-1)(b-1), 3, 3)."""
    first = np.stack([V[:-1, :-1], V[1:, :-1], V[1:, 1:]], -2).reshape(-1, 3, 3)
    second = np.stack([V[:-1, :-1], V[1:, 1:], V[:-1, 1:]], -2).reshape(-1, 3, 3)
    return np.concatenate([first, second])


def inputs():
    """The queries' fixed inputs (seeded)."""
    rng = np.random.default_rng(0)
    K = COUNTS["proxy segments"]
    # between points on the faces of a box 0.3 m around the shell's (the Cornell gather's
    # segments against it: all of them inside its box, about half of them blocked)
    lo, hi = np.array([3.1, 0.7, 2.5]), np.array([4.7, 2.2, 4.4])
    a, b = lo + (hi - lo) * rng.uniform(0.0, 1.0, (2, K, 3))
    for ends in (a, b):
        axis = rng.integers(0, 3, K)
        ends[np.arange(K), axis] = np.where(rng.integers(0, 2, K) == 1, hi[axis], lo[axis])
    D = b - a
    proxy = (a, D, np.linalg.norm(D, axis=1), np.full(K, 1e-9))
    polar, azimuth = np.meshgrid(np.linspace(0, np.pi, 33), np.linspace(0, 2 * np.pi, 65), indexing="ij")
    ball = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], -1)
    g = np.linspace(-4.0, 4.0, 41)
    X, Y = np.meshgrid(g, g, indexing="ij")
    floor = np.stack([X, Y, np.full_like(X, -1.0)], -1)
    triangles = np.concatenate([_grid_triangles(ball), _grid_triangles(floor)])
    R = COUNTS["BVH segments"]
    p, q = rng.uniform(-4.0, 4.0, (2, R, 3))
    p[:, 2], q[:, 2] = rng.uniform(-0.99, 3.0, (2, R))
    E = 5000
    linear = np.eye(3)[None] * rng.uniform(0.1, 0.3, (E, 1, 1))
    offset = rng.uniform(0.0, 10.0, (E, 3))
    S = COUNTS["BVH shafts"]
    s0, s1 = rng.uniform(0.0, 10.0, (2, S, 3))
    radius = rng.uniform(0.05, 0.5, S)
    box = (np.minimum(s0, s1) - radius[:, None], np.maximum(s0, s1) + radius[:, None])
    centre, size = rng.uniform(0.0, 10.0, (144, 3)), rng.uniform(0.2, 0.5, 144)
    B = COUNTS["ball segments"]
    which = rng.integers(0, 144, B)
    start = rng.uniform(0.0, 10.0, (B, 3))
    end = start + 2.0 * (centre[which] + rng.normal(0.0, 0.5, (B, 3)) - start)
    return (
        proxy,
        (triangles, p, q),
        ((linear, offset), box, s0, s1, radius),
        (centre, size, start, end, which),
    )


def _digest(*arrays):
    h = hashlib.sha1()
    for x in arrays:
        h.update(np.ascontiguousarray(x).tobytes())
    return h.hexdigest()[:12]


def measure(core_root, repeats=3):
    """Best-of-`repeats` seconds per query, and a hash of each answer, with the core at core_root."""
    sys.path.insert(0, str(core_root))
    from core import Sphere
    from core.bvh import BVH
    from core.occlusion import Occluders, _Proxy

    # (the shell from this checkout's benchmark, whichever core is measured)
    spec = importlib.util.spec_from_file_location("scene_scaling", ROOT / "benchmarks" / "scene_scaling.py")
    scene_scaling = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(scene_scaling)
    proxy_args, (triangles, p, q), (ellipsoids, box, s0, s1, radius), ball_args = inputs()
    centre, size, ray_start, ray_end, which = ball_args
    spheres = Occluders([Sphere(tuple(c), float(r)) for c, r in zip(centre, size)])
    shell = _Proxy(scene_scaling.nurbs_shell(), None)
    mesh = BVH.from_primitives(triangles=triangles)
    balls = BVH.from_primitives(ellipsoids=ellipsoids)
    calls = {
        "proxy segments": lambda: (shell.blocked(*proxy_args),),
        "BVH segments": lambda: (mesh.segments_blocked(p, q, 1e-9),),
        "BVH shafts": lambda: balls.shaft_candidates(box[0], box[1], s0, s1, radius),
        "ball segments": lambda: (spheres.blocked(ray_start, ray_end, which),),
    }
    out = {}
    for name, call in calls.items():
        best = np.inf
        for _ in range(repeats):
            start = time.perf_counter()
            result = call()
            best = min(best, time.perf_counter() - start)
        out[name] = (best, _digest(*result))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="a189b0a")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    from .revisions import interleaved  # (here: the processes measured import this file alone)

    now, before, commit = interleaved(Path(__file__).resolve(), args.before, args.rounds)
    lines = [
        f"Occlusion queries, this checkout ({commit}) against {args.before}, median of "
        f"{args.rounds} interleaved processes (each the best of 3 calls):",
        "",
        "| query | count | before (µs each) | now (µs each) | now / before | same answers |",
        "|---|---|---|---|---|---|",
    ]
    for name in QUERIES:
        t_now = float(np.median([r[name][0] for r in now]))
        t_before = float(np.median([r[name][0] for r in before]))
        same = {r[name][1] for r in now} == {r[name][1] for r in before}
        n = COUNTS[name]
        lines.append(
            f"| {name} | {n:,} | {t_before / n * 1e6:.2f} | {t_now / n * 1e6:.2f} | "
            f"{t_now / t_before:.2f} | {'yes' if same else 'NO'} |"
        )
    print("\n".join(lines))
    return lines


if __name__ == "__main__":
    main()
