"""Kernel throughput (issue 5, part b): kernel evaluations per second of the default method against
a bare vectorised numpy reference of the *same* kernel, in the same process.

What "same kernel" means. The default method integrates the outer patch adaptively and, at every
outer node, calls the inner evaluator `FormFactorSolver.inner` (`core.inner.PointToPatch`): an
exact contour integral for flat quads (`polygon.point_to_polygon`), sphere, disk and cylinder
patches, r^2 cos / d^3 for a whole sphere above the point's horizon, adaptive cubature otherwise
(GENERIC kind: its count then includes its own cell work). Its `evaluations` count those terms (one
per point plus one per edge, arc or sweep integrated in closed form), not point pairs. So for each
run the inputs (point, unit normal, inner patch, tolerance) the method hands to `solver.inner` are
recorded in an extra, untimed run (a uniform reservoir sample of up to RESERVOIR rows), K rows are
drawn from them (K chosen so one call takes ~0.3 s) and the bare evaluator is timed on them, once
as one call on all K rows and once in NODE_CHUNK-row slices as the method feeds it (numpy is
faster on cache-sized arrays); the faster of the two is the bare rate. The seed's fixed Gauss rule
is compared with the point-pair kernel `core.kernel.kernel` on 1e6 random point pairs of the same
two surfaces.

Runs: single pairs through `core.form_factor_estimate` (median of 5), batched pairs through
`FormFactorSolver(...).pairs` (construction included, as in `core.form_factors`, which does not
return the count; median of 3, or one run if it takes longer than BUDGET s), and the fixed cost
of one `form_factor_estimate` call on a far pair (latency: it bounds the rate of small single
pairs).

Run alone: python -m benchmarks.throughput
"""

import numpy as np

import core
from core.formfactor import NODE_CHUNK, FormFactorSolver
from core.inner import CYLINDER, DISK, FAR_EXACT, GENERIC, POLYGON, SPHERE
from core.kernel import kernel

from .common import bench_cases, square6, timed

RESERVOIR = 200_000  # recorded inner-evaluator inputs per run
CALL_SECONDS = 0.3  # target duration of one bare call
BUDGET = 2.0  # batched runs slower than this (s) are run once
KINDS = {
    GENERIC: "adaptive cubature",
    POLYGON: "polygon",
    SPHERE: "sphere patch",
    DISK: "disk patch",
    CYLINDER: "cylinder patch",
}


class Recorder:
    """Stands in for `solver.inner`: passes every call through and keeps a uniform random sample
    (reservoir, algorithm R) of the rows it was given.

    rows : ndarray, shape (min(seen, size), 8)
        Per row: x1 (3 columns, m), unit n1 (3), inner patch slot (1), absolute tolerance (1).
    """

    def __init__(self, inner, size=RESERVOIR, seed=0):
        self.inner, self.size, self.seen = inner, size, 0
        self.rng = np.random.default_rng(seed)
        self._rows = np.empty((size, 8))

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __call__(self, x1, n1, patch, tolerance):
        index = self.seen + np.arange(len(x1))  # rows seen before each one
        slot = np.where(index < self.size, index, (self.rng.random(len(x1)) * (index + 1)).astype(np.int64))
        keep = slot < self.size
        self._rows[slot[keep]] = np.column_stack([x1, n1, patch, tolerance])[keep]
        self.seen += len(x1)
        return self.inner(x1, n1, patch, tolerance)

    @property
    def rows(self):
        return self._rows[: min(self.seen, self.size)]


def bare_rate(function, columns, seed=1):
    """Best evaluations/s of `function` on rows drawn from `columns`.

    Parameters
    ----------
    function : callable(*columns) -> int
        Evaluates the given rows, returns its evaluation count.
    columns : list of ndarray, each shape (R, ...)
        Input rows; K of them are drawn with replacement, K such that one call takes ~CALL_SECONDS.

    Returns
    -------
    rate : float
        Evaluations/s, the faster of one call on all K rows and K rows in NODE_CHUNK slices (median
        of 3 each).
    how : str
        Which of the two, and K.
    """
    rng = np.random.default_rng(seed)

    def draw(k):
        pick = rng.integers(0, len(columns[0]), k)
        return [c[pick] for c in columns]

    probe = draw(10_000)
    _, seconds = timed(function, *probe, repeat=1)
    k = int(np.clip(CALL_SECONDS * 10_000 / seconds, 10_000, 1_000_000))
    sample = draw(k)

    def sliced():
        return sum(function(*(c[s : s + NODE_CHUNK] for c in sample)) for s in range(0, k, NODE_CHUNK))

    count1, seconds1 = timed(function, *sample, repeat=3)
    count2, seconds2 = timed(sliced, repeat=3)
    if count1 / seconds1 >= count2 / seconds2:
        return count1 / seconds1, f"one call, K={k}"
    return count2 / seconds2, f"{NODE_CHUNK}-row calls, K={k}"


def inner_kinds(inner, x1, n1, patch):
    """'polygon 100%'-style mix of the branches `PointToPatch.__call__` takes for the given rows
    (mirrors its tests: whole sphere above the horizon first, then far patches to cubature)."""
    far = inner.root_radius[patch] <= FAR_EXACT * np.linalg.norm(x1 - inner.root_center[patch], axis=-1)
    kind = np.array([KINDS[k] for k in np.where(far, GENERIC, inner.kind[patch])], dtype=object)
    height = np.einsum("ki,ki->k", inner.sphere_center[patch] - x1, n1)
    kind[inner.whole_sphere[patch] & (height >= inner.sphere_radius[patch] * (1.0 + 1e-12))] = "whole sphere"
    names, counts = np.unique(kind, return_counts=True)
    order = np.argsort(-counts)
    return ", ".join(f"{names[i]} {100 * counts[i] / counts.sum():.0f}%" for i in order)


def nested_run(surfaces, source, target, tol, single):
    """Time one adaptive run and measure the bare rate of the inner evaluator on its recorded inputs.

    surfaces : list of Surface; source, target : index arrays into it, shape (P,).
    single : time `core.form_factor_estimate(surfaces[0], surfaces[1], tol)` instead of the batch.
    """
    solver = FormFactorSolver(surfaces)
    solver.inner = Recorder(solver.inner)
    _, _, evaluations = solver.pairs(source, target, tol)  # recording run (also a warm-up for singles)
    if single:
        est, seconds = timed(core.form_factor_estimate, surfaces[0], surfaces[1], tol=tol, repeat=5)
        assert est.evaluations == evaluations
    else:

        def batch():
            return FormFactorSolver(surfaces).pairs(source, target, tol)[2]

        _, seconds = timed(batch, repeat=3, budget=BUDGET)
    rows, points, inner = solver.inner.rows, solver.inner.seen, solver.inner.inner
    x1, n1, patch, tolerance = rows[:, :3], rows[:, 3:6], rows[:, 6].astype(np.int64), rows[:, 7]
    rate, how = bare_rate(lambda *c: inner(*c)[2], [x1, n1, patch, tolerance])
    return dict(
        evaluations=evaluations,
        seconds=seconds,
        bare_rate=rate,
        bare_how=how,
        kernel=inner_kinds(inner, x1, n1, patch),
        points=points,
    )


def point_pair_rate(a, b, pairs=1_000_000, seed=0):
    """Rate of `core.kernel.kernel` on random point pairs of patches a and b (unit normal on a)."""
    rng = np.random.default_rng(seed)

    def points(s):
        (u0, u1), (v0, v1) = s.domain
        return s.evaluate(rng.uniform(u0, u1, pairs), rng.uniform(v0, v1, pairs))

    (x1, n1), (x2, n2) = points(a), points(b)
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    return bare_rate(lambda *c: kernel(*c).size, [x1, n1, x2, n2])


def measure(verbose=True):
    cases = {c.id: c for c in bench_cases()}

    def case(cid, nu=1, nv=1):
        (a,), b = cases[cid].build()
        return a.split(nu, nv), b.split(nu, nv)

    def seed():
        return [core.Sphere((0, 0, 6), 1.0)], [square6()]

    def sphere_square():
        return core.Sphere((0, 0, 6), 1.0).split(4, 8), square6().split(8, 8)

    def spheres_square(n=256):  # whole spheres r=1 at random centres above the square: the seed's kernel
        c = np.random.default_rng(0).uniform((-3, -3, 3), (3, 3, 9), (n, 3))
        return [core.Sphere(tuple(p), 1.0) for p in c], [square6()]

    runs = [  # label, (sources, targets), tol
        ("seed sphere->square, single, tol=1e-6", seed, 1e-6),
        ("seed sphere->square, single, tol=1e-10", seed, 1e-10),
        ("sphere->sphere, single, tol=1e-8", lambda: case("sphere_to_sphere"), 1e-8),
        ("coaxial cylinders, single, tol=1e-8", lambda: case("coaxial_cylinders"), 1e-8),
        ("256 whole spheres -> square, batch, tol=1e-10", spheres_square, 1e-10),
        ("sphere (4x8) x square (8x8), batch, tol=1e-3", sphere_square, 1e-3),
        ("sphere (4x8) x square (8x8), batch, tol=1e-6", sphere_square, 1e-6),
        ("sphere (2x4) x sphere (2x4), batch, tol=1e-4", lambda: case("sphere_to_sphere", 2, 4), 1e-4),
        ("cylinder (8x2) x cylinder (8x2), batch, tol=1e-4", lambda: case("coaxial_cylinders", 8, 2), 1e-4),
    ]
    rows = []
    for label, build, tol in runs:
        A, B = build()
        i, j = np.meshgrid(np.arange(len(A)), np.arange(len(B)), indexing="ij")
        r = nested_run(list(A) + list(B), i.ravel(), len(A) + j.ravel(), tol, single=len(A) * len(B) == 1)
        rows.append(dict(label=label, pairs=len(A) * len(B), **r))

    # the seed's fixed rule: point pairs, against the point-pair kernel on the same surfaces
    (a,), (b,) = seed()
    est, seconds = timed(core.form_factor_estimate, a, b, method="gauss", order=64, repeat=3)
    pp_rate, pp_how = point_pair_rate(a, b)
    rows.append(
        dict(
            label="seed sphere->square, single, gauss n=64",
            pairs=1,
            evaluations=est.evaluations,
            seconds=seconds,
            bare_rate=pp_rate,
            bare_how=pp_how,
            kernel="point pair (core.kernel)",
            points=None,
        )
    )
    for r in rows:
        r["rate"] = r["evaluations"] / r["seconds"]
        r["ratio"] = r["bare_rate"] / r["rate"]

    # fixed cost of one call: a far pair (whole sphere 1000 above the square: the seed's code path)
    a, b = core.Sphere((0, 0, 1000), 1.0), square6()
    far, latency = timed(core.form_factor_estimate, a, b, tol=1e-6, repeat=21)
    _, setup = timed(FormFactorSolver, [a, b], repeat=21)
    out = dict(
        point_pair_rate=pp_rate,
        chunk=NODE_CHUNK,
        rows=rows,
        latency=dict(seconds=latency, setup_seconds=setup, evaluations=far.evaluations),
    )
    if verbose:
        print(f"point-pair kernel core.kernel.kernel, sphere/square: {pp_rate:.3g} evaluations/s ({pp_how})")
        print(
            f"fixed cost of one form_factor_estimate call (sphere 1000 above the square, {far.evaluations} "
            f"evaluations): {latency * 1e3:.2f} ms, of which FormFactorSolver set-up {setup * 1e3:.2f} ms"
        )
        head = f"{'run':<50}{'evals':>10}{'time':>10}{'evals/s':>10}{'bare':>10}{'bare/this':>10}"
        print(head + "  inner kernel (bare timing)")
        for r in rows:
            print(
                f"{r['label']:<50}{r['evaluations']:>10d}{r['seconds'] * 1e3:>8.1f}ms{r['rate']:>10.3g}"
                f"{r['bare_rate']:>10.3g}{r['ratio']:>9.2f}x  {r['kernel']} ({r['bare_how']})"
            )
    return out


if __name__ == "__main__":
    measure()
