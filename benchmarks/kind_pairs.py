"""Every pair of surface kinds: time and accuracy of `form_factor_estimate` at tol 1e-6.

A fixed random set of pairs (seeded) over the kinds below, each placed at a random gap (contact
to far), orientation and, for some, a random sub-patch. Each pair runs in its own process with a
timeout. The reference is independent of the adaptive code: a brute-force tensor Gauss-Legendre
rule on a uniform grid of cells over both parameter domains, at two resolutions; their
difference is the reference's own uncertainty, and a result counts as outside tol when
|F - F_ref| > tol F_ref + that uncertainty, and again against 24 cells a side (uncertainty: its
difference from 12), since two coarse rules can agree by chance where the clipped kernel kinks.
Pairs whose reference is not converged to 1e-4 are listed as "ref?" (their accuracy is not
judged).

    python -m benchmarks.kind_pairs [--pairs 200] [--timeout 30] [--seed 1] [--generic] [--only 31,49]

--generic keeps only the pairs of the set in which neither side has an exact inner integral
(ellipsoids, twisted quads, NURBS, their sub-patches), the slow ones.

Prints a markdown table: per kind pair, the count, p50 / p99 / max wall time (a timeout counts
as its limit), results outside tol, timeouts and unjudged references.
"""

import argparse
import multiprocessing as mp
import time

import numpy as np

import core
from core.formfactor import FormFactorSolver
from core.kernel import kernel
from core.quadrature import tensor_rule
from tests.test_generic_pairs import blender_tube, height_field

KINDS = (
    "sphere",
    "ellipsoid",
    "quad",
    "twisted_quad",
    "triangle",
    "disk",
    "cylinder",
    "nurbs",
    "nurbs_rational",
    "nurbs_cyclic",
    "subpatch",
)
TOL = 1e-6
S = np.sqrt(0.5)
CIRCLE = np.array([(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0)], float)
CIRCLE_W = np.array([1, S, 1, S, 1, S, 1, S, 1])
CIRCLE_KNOTS = [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1]


def rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def place(surface, rng, offset):
    """Random rotation, then a shift by `offset`."""
    M = np.eye(4)
    M[:3, :3] = rotation(rng)
    M[:3, 3] = offset
    return surface.transformed(M)


def make(kind, rng):
    """A surface of size about 1 centred near the origin (before placement)."""
    if kind == "sphere":
        return core.Sphere((0, 0, 0), rng.uniform(0.3, 0.8))
    if kind == "ellipsoid":
        M = np.diag(np.r_[rng.uniform(0.3, 0.9, 3), 1.0])
        return core.Sphere((0, 0, 0), 1.0).transformed(M)
    if kind == "quad":
        a, b = rng.uniform(0.5, 1.5, 2)
        return core.Quad((-a, -b, 0), (a, -b, 0), (a, b, 0), (-a, b, 0))
    if kind == "twisted_quad":
        h = rng.uniform(0.2, 0.6)
        return core.Quad((-1, -1, -h), (1, -1, h), (1, 1, -h), (-1, 1, h))
    if kind == "triangle":
        p = rng.uniform(-1, 1, (3, 2))
        p = np.c_[p, np.zeros(3)]
        if np.cross(p[1] - p[0], p[2] - p[0])[2] < 0:
            p = p[[0, 2, 1]]
        return core.Quad(p[0], p[1], p[2], p[0])
    if kind == "disk":
        return core.Disk((0, 0, 0), (0, 0, 1), rng.uniform(0.4, 1.0))
    if kind == "cylinder":
        return core.Cylinder((0, 0, -0.5), (0, 0, 1), rng.uniform(0.3, 0.7), rng.uniform(0.5, 1.5))
    if kind == "nurbs":  # a non-rational bicubic height field
        return height_field(0.3 * rng.standard_normal((5, 5)))
    if kind == "nurbs_rational":  # an exact NURBS sphere patch or whole sphere (P&T ch. 7-8)
        r = rng.uniform(0.4, 0.8)
        half = np.array([(0, -1), (1, -1), (1, 0), (1, 1), (0, 1)], float)
        half_w = np.array([1, S, 1, S, 1])
        points = r * np.stack(
            [
                CIRCLE[:, None, 0] * half[None, :, 0],
                CIRCLE[:, None, 1] * half[None, :, 0],
                np.broadcast_to(half[None, :, 1], (9, 5)),
            ],
            -1,
        )
        weights = CIRCLE_W[:, None] * half_w[None, :]
        surface = core.NurbsSurface(points, weights, 3, 3, CIRCLE_KNOTS, [0, 0, 0, 0.5, 0.5, 1, 1, 1])
        if rng.random() < 0.5:
            (u0, u1), (v0, v1) = surface.domain
            surface = surface.subpatch(u=(u0, u0 + rng.uniform(0.3, 1.0) * (u1 - u0)))
        return surface
    if kind == "nurbs_cyclic":  # a bumpy open tube, cyclic in u as Blender builds it (`from_blender`)
        order = int(rng.integers(3, 5))
        return blender_tube(rng.uniform(0.4, 0.7) * (1 + 0.1 * rng.standard_normal((4, 8))), order)
    if kind == "subpatch":
        base = make(("sphere", "ellipsoid", "cylinder", "nurbs")[rng.integers(4)], rng)
        (u0, u1), (v0, v1) = base.domain
        a = np.sort(rng.uniform(0, 1, 2))
        b = np.sort(rng.uniform(0, 1, 2))
        a[1] = max(a[1], a[0] + 0.2)
        b[1] = max(b[1], b[0] + 0.2)
        a, b = np.minimum(a, 1.0), np.minimum(b, 1.0)
        return base.subpatch(
            u=(u0 + a[0] * (u1 - u0), u0 + a[1] * (u1 - u0)), v=(v0 + b[0] * (v1 - v0), v0 + b[1] * (v1 - v0))
        )
    raise ValueError(kind)


def pairs(count, seed):
    """The fixed random set: (kind1, kind2, src, dst) tuples, kinds cycling over all pairs."""
    rng = np.random.default_rng(seed)
    kinds = [(a, b) for i, a in enumerate(KINDS) for b in KINDS[i:]]
    out = []
    for k in range(count):
        k1, k2 = kinds[k % len(kinds)]
        src = place(make(k1, rng), rng, (0, 0, 0))
        gap = 10 ** rng.uniform(-2, 0.5)
        dst = place(make(k2, rng), rng, rotation(rng)[0] * (2.0 + gap))
        # face each other at their centres where possible (random flips would zero half the set)
        for name in ("src", "dst"):
            s = src if name == "src" else dst
            other = dst if name == "src" else src
            u, v = np.mean(s.domain[0]), np.mean(s.domain[1])
            x, n = s.evaluate(u, v)
            xo, _ = other.evaluate(np.mean(other.domain[0]), np.mean(other.domain[1]))
            if n @ (xo - x) < 0:
                s = s.flipped()
            src, dst = (s, dst) if name == "src" else (src, s)
        out.append((k1, k2, src, dst))
    return out


def brute_force(src, dst, cells, order=5):
    """F(src -> dst) by a tensor Gauss rule on cells x cells sub-boxes of each domain (no adaptivity)."""
    s, t, w = tensor_rule(order)

    def nodes(surface):
        (u0, u1), (v0, v1) = surface.domain
        du, dv = (u1 - u0) / cells, (v1 - v0) / cells
        i, j = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
        u = (u0 + (i.ravel()[:, None] + s) * du).ravel()
        v = (v0 + (j.ravel()[:, None] + t) * dv).ravel()
        x, n = surface.evaluate(u, v)
        return x, n, np.tile(w, cells * cells) * du * dv

    x1, n1, w1 = nodes(src)
    x2, n2, w2 = nodes(dst)
    total = 0.0
    rows = max(1, 4_000_000 // len(x2))
    for start in range(0, len(x1), rows):
        part = slice(start, start + rows)
        k = kernel(x1[part, None], n1[part, None], x2[None], n2[None])
        total += (w1[part, None] * k * w2[None]).sum()
    return total / src.area()


def _run(src, dst, queue):
    start = time.perf_counter()
    try:
        est = core.form_factor_estimate(src, dst, tol=TOL)
        queue.put((est.value, est.error, time.perf_counter() - start, None))
    except Exception as exc:  # reported in the table, not hidden
        queue.put((np.nan, np.nan, time.perf_counter() - start, repr(exc)))


def timed_pair(src, dst, timeout):
    """(value, error, seconds, problem) of one pair in its own process; problem is 'timeout' etc."""
    queue = mp.get_context("fork").Queue()
    process = mp.get_context("fork").Process(target=_run, args=(src, dst, queue))
    start = time.perf_counter()
    process.start()
    process.join(timeout)
    if process.is_alive():
        process.terminate()
        process.join()
        return np.nan, np.nan, timeout, "timeout"
    try:
        return queue.get(timeout=5)
    except Exception:
        return np.nan, np.nan, time.perf_counter() - start, "crashed"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=200)
    parser.add_argument("--timeout", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--generic", action="store_true", help="only pairs with no exact inner side")
    parser.add_argument("--only", default="", help="comma-separated pair indices to run (a subset)")
    args = parser.parse_args(argv)
    only = {int(k) for k in args.only.split(",") if k.strip()}
    rows = {}
    for index, (k1, k2, src, dst) in enumerate(pairs(args.pairs, args.seed)):
        if only and index not in only:
            continue
        if args.generic and FormFactorSolver([src, dst]).exact_inner.any():
            continue
        value, error, seconds, problem = timed_pair(src, dst, args.timeout)
        coarse, fine = brute_force(src, dst, 6), brute_force(src, dst, 12)
        uncertainty = abs(fine - coarse)
        judged = uncertainty <= 1e-4 * max(fine, 1e-12) or fine == 0.0
        outside = problem is None and judged and abs(value - fine) > TOL * fine + uncertainty
        if outside:
            # a second look before calling it outside: the 6- and 12-cell rules can agree by chance
            # where the clipped kernel kinks (touching or crossing pairs); 24 cells a side
            coarse, fine = fine, brute_force(src, dst, 24)
            uncertainty = abs(fine - coarse)
            outside = abs(value - fine) > TOL * fine + uncertainty
        row = rows.setdefault((k1, k2), {"t": [], "out": 0, "timeout": 0, "ref": 0, "fail": 0})
        row["t"].append(seconds)
        row["out"] += bool(outside)
        row["timeout"] += problem == "timeout"
        row["fail"] += problem not in (None, "timeout")
        row["ref"] += not judged
        print(
            f"# {index:3d} {k1:>14s} -> {k2:<14s} F={value:.10g} err={error:.2g} ref={fine:.10g} "
            f"+-{uncertainty:.1g} {seconds:.2f}s {problem or ''}{' OUTSIDE' if outside else ''}",
            flush=True,
        )
    print()
    print(f"tol {TOL:g}, {args.pairs} pairs, timeout {args.timeout:g} s, seed {args.seed}")
    print()
    print("| kinds | n | p50 (s) | p99 (s) | max (s) | outside tol | timeouts | errors | ref? |")
    print("|---|---|---|---|---|---|---|---|---|")
    every = []
    for (k1, k2), row in sorted(rows.items()):
        t = np.array(row["t"])
        every.extend(t)
        print(
            f"| {k1}-{k2} | {t.size} | {np.percentile(t, 50):.2f} | {np.percentile(t, 99):.2f} | "
            f"{t.max():.2f} | {row['out']} | {row['timeout']} | {row['fail']} | {row['ref']} |"
        )
    every = np.array(every)
    totals = {key: sum(r[key] for r in rows.values()) for key in ("out", "timeout", "fail", "ref")}
    print(
        f"| all | {every.size} | {np.percentile(every, 50):.2f} | {np.percentile(every, 99):.2f} | "
        f"{every.max():.2f} | {totals['out']} | {totals['timeout']} | {totals['fail']} | {totals['ref']} |"
    )


if __name__ == "__main__":
    main()
