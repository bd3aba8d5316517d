"""Shared helpers for the benchmarks: timing, test cases with exact values, flat tessellation,
Monte Carlo and the pyviewfactor comparison.

Nothing here is imported by core/ or addon/; matplotlib and pyviewfactor are only used by the
benchmark scripts (requirements-bench.txt).
"""

import os
import statistics
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

import core

# exact values: tests/reference/view_factors.py, where each one cites its source
SEED_EXACT = 0.0640942168489749  # atan(1/sqrt(24))/pi: sphere_above_square_centre(6, 6) (EES f3d_7, C-124)


def timed(function, *args, repeat=3, budget=None, **kwargs):
    """Run function(*args, **kwargs) `repeat` times; return (last result, median wall time in s).

    With `budget` (s), a first run slower than the budget is not repeated.
    """
    times = []
    result = None
    for k in range(repeat):
        start = time.perf_counter()
        result = function(*args, **kwargs)
        times.append(time.perf_counter() - start)
        if budget is not None and k == 0 and times[0] > budget:
            break
    return result, statistics.median(times)


def relative(value, exact):
    return abs(value - exact) / abs(exact)


# ---------------------------------------------------------------------------- cases
def square6():
    return core.Quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0))


def cube_face():
    """Bottom face of the cube of side 12 centred at the origin, facing +z (inwards)."""
    return core.Quad((-6, -6, -6), (6, -6, -6), (6, 6, -6), (-6, 6, -6))


@dataclass
class Case:
    """A benchmark configuration: F(sum of sources -> target) against an exact value.

    sources : list of Surface (the value is the area-weighted sum over them: F = sum A_p F_p / A)
    target : Surface
    """

    id: str
    title: str
    build: Callable
    exact: float
    source: str
    curved_target: bool = False
    extra: dict = field(default_factory=dict)


def bench_cases():
    from tests.reference import view_factors as vf

    seed_src = (
        "sphere_above_square_centre (tests/reference/view_factors.py): EES f3d_7 / Tripp, Hwang & Crank "
        "1962 in Howell 1982 p. 190; Howell C-121/C-124"
    )
    s2s = vf.case("sphere_to_sphere_equal_3R")
    cyl = vf.case("coaxial_cylinders_inner_to_outer")
    sdisk = vf.case("sphere_to_coaxial_disk")
    return [
        Case(
            "seed_sphere_square",
            "Seed 1: sphere r=1, centre 6 above a 6x6 square",
            lambda: ([core.Sphere((0, 0, 6), 1.0)], square6()),
            SEED_EXACT,
            seed_src,
        ),
        Case(
            "sphere_in_cube",
            "Seed 2: sphere r=1 in a cube of side 12 -> one face (whole sphere)",
            lambda: ([core.Sphere((0, 0, 0), 1.0)], cube_face()),
            1.0 / 6.0,
            "1/6 by symmetry; sphere_to_rectangle (Howell C-124) in tests/reference/view_factors.py",
        ),
        Case(
            "sphere_in_cube_16",
            "Seed 2: sphere r=1 in a cube of side 12 -> one face (sphere split into 16 patches)",
            lambda: (core.Sphere((0, 0, 0), 1.0).split(4, 4), cube_face()),
            1.0 / 6.0,
            "1/6 by symmetry (summation F = sum A_p F_p / A)",
            extra={"skip_flat": True},  # facets, Monte Carlo, pyviewfactor: as for the whole sphere
        ),
        Case(
            "sphere_to_sphere",
            "Curved-curved: sphere r=1 to sphere r=1, centres 3 apart",
            lambda: ([s2s.build()[0]], s2s.build()[1]),
            s2s.exact,
            "sphere_to_sphere (tests/reference/view_factors.py): integral of Howell B-43 (derived there; "
            "cf. Juul 1976)",
            curved_target=True,
        ),
        Case(
            "coaxial_cylinders",
            "Curved-curved: outside of cylinder r=0.5 to inside of coaxial cylinder r=1, length 2",
            lambda: ([cyl.build()[0]], cyl.build()[1]),
            cyl.exact,
            "coaxial_cylinders_inner_to_outer (tests/reference/view_factors.py): closed form, "
            "= (r2/r1) x S&H outer-to-inner (EES hs313)",
            curved_target=True,
            # flat facets of the two cylinders: core.form_factors did not return within 5 min for the
            # coarsest tessellation (2 x 4 facets each), so the flat/pyviewfactor series are skipped
            extra={"skip_flat": True},
        ),
        Case(
            "sphere_to_disk",
            "Curved-flat: sphere r=1, centre 2 above a coaxial disk R=3",
            lambda: ([sdisk.build()[0]], sdisk.build()[1]),
            sdisk.exact,
            "sphere_to_coaxial_disk (tests/reference/view_factors.py): EES f3d_16, Rohsenow et al. p. 7.84",
            # the disk is kept exact: with its rim tessellated (triangles from the centre), core.form_factors
            # on 8 x 4 flat facet pairs did not return within 100 s
            curved_target=False,
        ),
    ]


# ---------------------------------------------------------------------------- flat tessellation
def tessellate(surface, nu, nv):
    """Flat facets (core.Quad) through an nu x nv grid of points of `surface`.

    Each parameter cell gives the quad through its four corner points, oriented like the surface's
    front; a cell with a collapsed edge (a sphere pole, a disk centre) is a triangle (a Quad with
    p01 == p00); a non-planar cell is split into two triangles. Returns a list of core.Quad.
    """
    (u0, u1), (v0, v1) = surface.domain
    us, vs = np.linspace(u0, u1, nu + 1), np.linspace(v0, v1, nv + 1)
    P, _ = surface.evaluate(*np.meshgrid(us, vs, indexing="ij"))
    uc, vc = 0.5 * (us[:-1] + us[1:]), 0.5 * (vs[:-1] + vs[1:])
    _, N = surface.evaluate(*np.meshgrid(uc, vc, indexing="ij"))
    scale = np.ptp(P.reshape(-1, 3), axis=0).max()
    facets = []
    for i in range(nu):
        for j in range(nv):
            ring = [P[i, j], P[i + 1, j], P[i + 1, j + 1], P[i, j + 1]]
            # drop repeated corners (collapsed edges)
            pts = []
            for p in ring:
                if not pts or np.linalg.norm(p - pts[-1]) > 1e-12 * scale:
                    pts.append(p)
            if len(pts) > 1 and np.linalg.norm(pts[0] - pts[-1]) <= 1e-12 * scale:
                pts.pop()
            if len(pts) < 3:
                continue
            normal = np.cross(pts[1] - pts[0], pts[2] - pts[0])
            if len(pts) == 4:
                normal = np.cross(pts[2] - pts[0], pts[3] - pts[1])
            if normal @ N[i, j] < 0:
                pts = pts[::-1]
            if len(pts) == 3:
                facets.append(core.Quad(pts[0], pts[1], pts[2], pts[0]))
                continue
            n_unit = normal / np.linalg.norm(normal)
            off_plane = abs(n_unit @ (pts[3] - pts[0])) if len(pts) == 4 else 0.0
            if off_plane <= 1e-12 * scale:
                facets.append(core.Quad(*pts))
            else:
                facets.append(core.Quad(pts[0], pts[1], pts[2], pts[0]))
                facets.append(core.Quad(pts[0], pts[2], pts[3], pts[0]))
    return facets


def facet_polygons(facets):
    """Vertex arrays (k, 3) of flat core.Quad facets (triangles have 3 vertices)."""
    out = []
    for f in facets:
        if isinstance(f, core.Disk):  # an exact disk target: a 256-gon for pyviewfactor
            t = np.linspace(*f.domain[1], 257)[:-1]
            out.append(f.evaluate(np.full_like(t, f.domain[0][1]), t)[0])
            continue
        c = f.corners
        out.append(c[:3] if np.allclose(c[3], c[0], rtol=0, atol=0) else c)
    return out


def flat_tessellation_value(sources, target, resolution, curved_target, tol=1e-10):
    """F(sources -> target) with every curved surface replaced by flat facets (exact flat factors).

    Returns (value, facet count of the sources, target facet count, evaluations).
    """
    nu, nv = resolution
    src_facets = [f for s in sources for f in tessellate(s, nu, nv)]
    if curved_target:
        dst_facets = tessellate(target, *target_resolution(target, resolution))
    else:
        dst_facets = [target]
    F = core.form_factors(src_facets, dst_facets, tol=tol)
    areas = np.array([f.area() for f in src_facets])
    return float(areas @ F.sum(axis=1) / areas.sum()), len(src_facets), len(dst_facets)


def target_resolution(target, resolution):
    nu, nv = resolution
    if isinstance(target, core.Disk):
        return max(1, nu // 4), nv
    if isinstance(target, core.Cylinder):
        return nv, max(1, nu // 4)
    return nu, nv


def sphere_resolutions(levels):
    """(nu, nv) grids for a sphere: nv = 2 nu."""
    return [(n, 2 * n) for n in levels]


# ---------------------------------------------------------------------------- Monte Carlo
def _unit_kernel(x1, n1, x2, n2):
    """cos1 cos2 / (pi L^2) with unit normals, clipped to pairs facing each other."""
    e = x2 - x1
    L2 = np.einsum("...i,...i->...", e, e)
    c1 = np.einsum("...i,...i->...", n1, e)
    c2 = -np.einsum("...i,...i->...", n2, e)
    ok = (c1 > 0) & (c2 > 0) & (L2 > 0)
    return np.where(ok, c1 * c2 / (np.pi * np.where(ok, L2 * L2, 1.0)), 0.0)


def sample_area(surface, n, rng):
    """n points uniformly distributed in area on `surface` (rejection on the area density).

    Returns (points, unit front normals), shapes (n, 3).
    """
    (u0, u1), (v0, v1) = surface.domain
    g = np.linspace(0, 1, 65)
    _, N = surface.evaluate(*np.meshgrid(u0 + (u1 - u0) * g, v0 + (v1 - v0) * g, indexing="ij"))
    top = 1.05 * np.linalg.norm(N, axis=-1).max()
    xs, ns, have = [], [], 0
    while have < n:
        m = int(1.3 * (n - have)) + 16
        u = u0 + (u1 - u0) * rng.random(m)
        v = v0 + (v1 - v0) * rng.random(m)
        x, nn = surface.evaluate(u, v)
        d = np.linalg.norm(nn, axis=-1)
        keep = rng.random(m) * top < d
        xs.append(x[keep])
        ns.append(nn[keep] / d[keep, None])
        have += int(keep.sum())
    return np.concatenate(xs)[:n], np.concatenate(ns)[:n]


def monte_carlo(sources, target, n, seed=0, chunk=200_000):
    """Seeded Monte Carlo estimate of F(sources -> target) from n independent point pairs.

    Points are uniform in area on the union of the sources and on the target:
    F = A_target * mean(cos1 cos2 / (pi L^2)).
    """
    rng = np.random.default_rng(seed)
    areas = np.array([s.area() for s in sources])
    counts = rng.multinomial(n, areas / areas.sum())
    total = 0.0
    for s, k in zip(sources, counts):
        done = 0
        while done < k:
            m = min(chunk, k - done)
            x1, n1 = sample_area(s, m, rng)
            x2, n2 = sample_area(target, m, rng)
            total += _unit_kernel(x1, n1, x2, n2).sum()
            done += m
    return target.area() * total / n


# ---------------------------------------------------------------------------- pyviewfactor
def pyviewfactor_available():
    try:
        import pyviewfactor  # noqa: F401
        import pyvista  # noqa: F401
    except Exception:
        return False
    return True


def pyviewfactor_warmup():
    """Compile pyviewfactor's numba kernels once (not counted in any timing)."""
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    pyviewfactor_value([tri], [tri[::-1] + [0, 0, 1.0]])


def pyviewfactor_value(src_polys, dst_polys):
    """F(sources -> target) by pyviewfactor on flat facets, as a user would compute it.

    Both facet sets go into one pyvista mesh; `compute_viewfactor_matrix` (SA-30 kernel, its
    default rounding of coordinates to 8 decimals, visibility test on, obstruction off: the
    project's convention has no third-body occlusion) returns F[i, j] = F(j -> i); the source
    rows are summed with area weights. Returns (value, seconds of the matrix call).
    """
    import pyviewfactor as pvf
    import pyvista as pv

    polys = list(src_polys) + list(dst_polys)
    points = np.concatenate(polys).astype(np.float64)
    faces, start = [], 0
    for p in polys:
        faces.append([len(p), *range(start, start + len(p))])
        start += len(p)
    mesh = pv.PolyData(points, faces=np.concatenate(faces))
    t0 = time.perf_counter()
    F = pvf.compute_viewfactor_matrix(mesh, skip_obstruction=True)
    seconds = time.perf_counter() - t0
    ns = len(src_polys)
    areas = np.array([_polygon_area(p) for p in src_polys])
    # F[i, j] = F(j -> i): rows i are targets, columns j sources
    value = float(areas @ F[ns:, :ns].sum(axis=0) / areas.sum())
    return value, seconds


def _polygon_area(p):
    s = np.zeros(3)
    for k in range(1, len(p) - 1):
        s += np.cross(p[k] - p[0], p[k + 1] - p[0])
    return 0.5 * np.linalg.norm(s)


def limit_threads():
    """One thread for numba/BLAS so the comparison is single-core like core/ (shared machine)."""
    for name in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
