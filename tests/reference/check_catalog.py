"""Brute-force check of every case in tests/reference/view_factors.py (a script, not a pytest test).

For each case the 4D integral

    F(1 -> 2) = 1 / (pi A1) * integral integral max(0, n1 . d) max(0, -n2 . d) / |d|^4 du1 dv1 du2 dv2

(d = P2 - P1; n1, n2 the unnormalised front normals returned by `Surface.evaluate`, so the parameter
Jacobians are already in them) is estimated by randomised quasi-Monte Carlo: R = 16 independently
scrambled Sobol' point sets of 2^m points in [0, 1)^4 (scipy.stats.qmc only generates the points; with
52 bits: its default of 30 bits puts every point on a 2^-30 grid, a left Riemann sum whose bias,
~1e-9 relative, was visible in the smooth cases), mapped to the two parameter boxes. The replicate
estimates are independent: their mean is the estimate and std / sqrt(R) its standard error.

Near-singular cases: where a parameter edge of one surface meets the other surface at a crease (a
shared edge at an angle, the rim of a hemisphere on its base), the kernel behaves like 1/L^2 and plain
sampling has infinite variance; where they nearly touch with differing normals (spheres 1e-3 apart)
it is bounded only by ~1/gap^2.
Such edges are found from `evaluate` alone (`warp_flags`) and their coordinate is graded towards them
(`warp`: y ~ s^8 over the nearest 1/16 of the range), which makes the variance and the fourth moment
finite, so that the standard errors can be trusted (a milder sin-type warp, y ~ s^3, gave finite
variance only, and its errors were visibly skewed). These cases converge more slowly (~1e-3 relative,
against ~1e-5 to 1e-11 for the smooth ones; see the table printed at the end).

A1 comes from a 16 x 16-panel, 24 x 24-node Gauss-Legendre rule on |n1|. Only `Surface.evaluate(u, v)`,
`Surface.domain` and numpy are used: nothing from core's form-factor code. A case passes when
|estimate - exact| <= 4.5 standard errors (or within 1e-13 relative, the floating-point floor of the
sums).

Run from the repository root (about 4 minutes on one core; --quick about 20 s):

    .venv/bin/python tests/reference/check_catalog.py            # all cases
    .venv/bin/python tests/reference/check_catalog.py --quick    # 16x fewer points
    .venv/bin/python tests/reference/check_catalog.py c14 sphere_to_sphere   # ids containing these
"""

import argparse
import pathlib
import sys
import time

import numpy as np
from scipy.stats import qmc

ROOT = pathlib.Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tests.reference.view_factors import CASES  # noqa: E402

# log2 of the points per replicate; cases not listed use DEFAULT_M
DEFAULT_M = 19
HARD_M = {
    # shared edges at an angle (1/L^2 singularity along them) and nearly touching spheres
    "c14_perpendicular_rectangles": 21,
    "c14_rotated_translated": 21,
    "hemisphere_inside_to_base": 21,
    "base_to_hemisphere_inside": 21,
    "cylinder_lateral_to_end": 21,
    "cylinder_end_to_lateral": 21,
    "sphere_to_sphere_gap_1e-3": 23,
}
REPLICATES = 16
CHUNK = 1 << 16
Z_LIMIT = 4.5


# graded map towards a flagged edge: y = A (2 s)^P for s < 1/2 (half of the samples within the fraction
# A of the parameter range next to the edge), uniform over [A, 1] for s >= 1/2
GRADE_A = 1.0 / 16.0
GRADE_P = 8


def _graded(s):
    """Map of [0, 1] onto itself, y ~ s^P near 0, and its derivative."""
    low = s < 0.5
    x = 2.0 * np.minimum(s, 0.5)
    y = np.where(low, GRADE_A * x**GRADE_P, GRADE_A + (1.0 - GRADE_A) * (2.0 * s - 1.0))
    jac = np.where(low, 2.0 * GRADE_P * GRADE_A * x ** (GRADE_P - 1), 2.0 * (1.0 - GRADE_A))
    return y, jac


def warp(s, lo, hi):
    """Map of [0, 1] onto itself grading samples towards the ends flagged lo / hi, and its derivative.

    Near a crease the kernel grows like 1/L^2; with samples graded as y ~ s^8 towards the crease in
    each of the two surfaces, the weighted integrand has finite variance and finite fourth moment
    (so the replicate standard errors are themselves reliable: a grading y ~ s^p needs p > 2 for the
    former and p > 6 for the latter, by counting powers near the crease).
    """
    s = np.asarray(s, dtype=np.float64)
    if lo and hi:
        first = s < 0.5
        y_lo, j_lo = _graded(np.minimum(2.0 * s, 1.0))
        y_hi, j_hi = _graded(np.minimum(2.0 - 2.0 * s, 1.0))
        return np.where(first, 0.5 * y_lo, 1.0 - 0.5 * y_hi), np.where(first, j_lo, j_hi)
    if lo:
        return _graded(s)
    if hi:
        y, jac = _graded(1.0 - s)
        return 1.0 - y, jac
    return s, np.ones_like(s)


_INSET = 1e-7


def _unit(normals):
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0.0)


def _edges(surface, n):
    """Points and unit normals along the four edges u = u0, u = u1, v = v0, v = v1 (n each).

    Evaluated a hair inside the domain so that a collapsed edge (a pole) still has a normal.
    """
    (u0, u1), (v0, v1) = surface.domain
    t = np.linspace(_INSET, 1.0 - _INSET, n)
    u, v = u0 + (u1 - u0) * t, v0 + (v1 - v0) * t
    ua, ub = u0 + (u1 - u0) * _INSET, u1 - (u1 - u0) * _INSET
    va, vb = v0 + (v1 - v0) * _INSET, v1 - (v1 - v0) * _INSET
    edges = []
    for uu, vv in ((np.full(n, ua), v), (np.full(n, ub), v), (u, np.full(n, va)), (u, np.full(n, vb))):
        points, normals = surface.evaluate(uu, vv)
        edges.append((points, _unit(normals)))
    return edges


def _grid(surface, n):
    (u0, u1), (v0, v1) = surface.domain
    t = np.linspace(_INSET, 1.0 - _INSET, n)
    U, V = np.meshgrid(u0 + (u1 - u0) * t, v0 + (v1 - v0) * t, indexing="ij")
    points, normals = surface.evaluate(U, V)
    return points.reshape(-1, 3), _unit(normals.reshape(-1, 3))


def _closest(a, b):
    """(distance, i, j) of the closest pair a[i], b[j]."""
    best = (np.inf, 0, 0)
    for i in range(0, len(a), 16):
        d = a[i : i + 16, None, :] - b[None, :, :]
        dist2 = np.einsum("ijk,ijk->ij", d, d)
        k = np.unravel_index(np.argmin(dist2), dist2.shape)
        if np.sqrt(dist2[k]) < best[0]:
            best = (float(np.sqrt(dist2[k])), i + int(k[0]), int(k[1]))
    return best


def warp_flags(surface, other, near=0.02, n=96):
    """((u_lo, u_hi), (v_lo, v_hi)): which parameter edges of `surface` get samples graded towards them.

    An edge is warped when at least a quarter of it comes within `near` x (size of the pair) of the
    other surface where the two front normals differ (a crease such as a shared edge at an angle, or
    facing surfaces nearly touching): there the kernel has its (near-)singularity ~ 1/L^2. An edge
    that merely ends at the crease (the ends of a shared edge) is not warped. Where the two patches
    continue one smooth surface (equal normals: neighbouring patches of one sphere or cylinder, or a
    patch and itself) the kernel stays bounded and no warp is needed; nor is the seam of a closed
    direction (full azimuth) an edge. Decided from `evaluate` alone.
    """
    edges = _edges(surface, n)
    grid_self, _ = _grid(surface, n)
    grid_other, normals_other = _grid(other, n)
    both = np.concatenate([grid_self, grid_other])
    size = float(np.linalg.norm(both.max(0) - both.min(0)))
    flags = []
    for points, normals in edges:
        crease = 0
        for k in range(len(points)):
            dist, _, j = _closest(points[k : k + 1], grid_other)
            crease += dist <= near * size and float(normals[k] @ normals_other[j]) <= 0.999
        flags.append(crease >= len(points) // 4)
    # a seam of a closed direction (full azimuth: the opposite edges coincide) is not an edge
    seam_u = np.abs(edges[0][0] - edges[1][0]).max() <= 1e-5 * size
    seam_v = np.abs(edges[2][0] - edges[3][0]).max() <= 1e-5 * size
    u_flags = (False, False) if seam_u else (flags[0], flags[1])
    v_flags = (False, False) if seam_v else (flags[2], flags[3])
    return u_flags, v_flags


def sample(surface, s, t, flags=((False, False), (False, False))):
    """Points, unnormalised front normals and warp Jacobian for unit-square samples (s, t)."""
    (u0, u1), (v0, v1) = surface.domain
    ws, js = warp(s, *flags[0])
    wt, jt = warp(t, *flags[1])
    points, normals = surface.evaluate(u0 + (u1 - u0) * ws, v0 + (v1 - v0) * wt)
    return points, normals, (u1 - u0) * (v1 - v0) * js * jt


def area(surface, panels=16, nodes=24):
    """Area of a patch by composite Gauss-Legendre on |evaluate(u, v)[1]|."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    (u0, u1), (v0, v1) = surface.domain
    eu = np.linspace(u0, u1, panels + 1)
    ev = np.linspace(v0, v1, panels + 1)
    uu = (eu[:-1, None] + np.diff(eu)[:, None] * x).ravel()
    wu = (np.diff(eu)[:, None] * w).ravel()
    vv = (ev[:-1, None] + np.diff(ev)[:, None] * x).ravel()
    wv = (np.diff(ev)[:, None] * w).ravel()
    U, V = np.meshgrid(uu, vv, indexing="ij")
    density = np.linalg.norm(surface.evaluate(U, V)[1], axis=-1)
    return float(wu @ density @ wv)


def integrand_sum(src, dst, pts, flags):
    """Sum over the points of max(0, n1.d) max(0, -n2.d) / (pi |d|^4) times the Jacobians."""
    P1, N1, J1 = sample(src, pts[:, 0], pts[:, 1], flags[0])
    P2, N2, J2 = sample(dst, pts[:, 2], pts[:, 3], flags[1])
    d = P2 - P1
    L2 = np.einsum("ij,ij->i", d, d)
    c1 = np.maximum(0.0, np.einsum("ij,ij->i", N1, d))
    c2 = np.maximum(0.0, -np.einsum("ij,ij->i", N2, d))
    ok = L2 > 0.0
    a = np.divide(c1, L2, out=np.zeros_like(L2), where=ok)
    b = np.divide(c2, L2, out=np.zeros_like(L2), where=ok)
    return float(np.sum(a * b * J1 * J2)) / np.pi


def estimate(src, dst, m, replicates=REPLICATES, seed=20240601):
    """(mean, standard error) of F(src -> dst) over `replicates` scrambled Sobol' sets of 2^m points."""
    a1 = area(src)
    flags = (warp_flags(src, dst), warp_flags(dst, src))
    rng = np.random.default_rng(seed)
    values = []
    for _ in range(replicates):
        sobol = qmc.Sobol(d=4, scramble=True, bits=52, seed=rng)
        pts = sobol.random_base2(m)
        total = sum(integrand_sum(src, dst, pts[i : i + CHUNK], flags) for i in range(0, len(pts), CHUNK))
        values.append(total / len(pts) / a1)
    values = np.array(values)
    return float(values.mean()), float(values.std(ddof=1) / np.sqrt(replicates))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ids", nargs="*", help="only cases whose id contains one of these")
    parser.add_argument("--quick", action="store_true", help="16x fewer points per replicate")
    args = parser.parse_args(argv)
    cases = [c for c in CASES if not args.ids or any(k in c.id for k in args.ids)]
    header = f"{'case':42s} {'exact':>22s} {'estimate':>22s} {'std err':>9s} {'rel err':>9s} {'z':>6s}"
    print(header)
    print("-" * len(header))
    failures = []
    start = time.perf_counter()
    for c in cases:
        m = HARD_M.get(c.id, DEFAULT_M) - (4 if args.quick else 0)
        src, dst = c.build()
        est, err = estimate(src, dst, m)
        diff = est - c.exact
        floor = 1e-13 * abs(c.exact)
        z = abs(diff) / err if err > 0.0 else (0.0 if abs(diff) <= floor else np.inf)
        ok = z <= Z_LIMIT or abs(diff) <= floor
        rel = err / abs(c.exact) if c.exact != 0.0 else err
        flag = "" if ok else "  <-- FAIL"
        print(f"{c.id:42s} {c.exact:22.16g} {est:22.16g} {err:9.2e} {rel:9.2e} {z:6.2f}{flag}", flush=True)
        if not ok:
            failures.append(c.id)
    print(f"\n{len(cases)} cases, {len(failures)} failed, {time.perf_counter() - start:.0f} s")
    if failures:
        print("failed:", ", ".join(failures))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
