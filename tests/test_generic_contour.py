"""The contour (Stokes / Sparrow) inner integral over cells of generic patches (`core.cellcontour`).

For a cell that a point sees wholly above its horizon and front on, F(dA1 -> cell) is
-1/(2 pi) times the contour integral of n1 . (R x dR) / |R|^2 around the cell's boundary
(Sparrow 1963). Checked against exact values and against the line rule it replaces:
- a NURBS net that is exactly a flat square (with a non-affine parametrisation) against the
  exact polygon integral (`polygon.point_to_polygon`), points seeing it wholly or in part;
- an exact rational NURBS octant of a sphere (a pole edge of zero length) against the exact
  sphere-patch contour (`contour.sphere_patch`) of the same octant as a `core.Sphere` patch;
- twisted bilinear quads and bicubic NURBS with interior knots against the line rule alone
  (the contour switched off), random points and orientations;
- invariance under a similarity map of point and patch, and under mirroring (reversed front);
- cells straddling a knot line never take the contour (its edges would not be analytic);
- `adaptive.integrate_cells` takes a final cell as it is (its halves are not evaluated).
"""

import numpy as np
import pytest

import core
import core.inner as inner_module
from core.adaptive import SPLIT_NONE, CellBatch, integrate_cells
from core.cellcontour import NODES, contour_rule, quadpack_error
from core.formfactor import FormFactorSolver
from core.inner import GENERIC, POLYGON
from tests.test_nurbs import nurbs_sphere

KNOTS4 = [0, 0, 0, 0, 1, 1, 1, 1]


def flat_nurbs_square(half=1.0):
    """A bicubic Bezier patch that is exactly the square [-half, half]^2 at z = 0, front +z,
    with interior control points moved within the plane (a non-affine parametrisation)."""
    i, j = np.meshgrid(np.linspace(-half, half, 4), np.linspace(-half, half, 4), indexing="ij")
    P = np.stack([i, j, np.zeros_like(i)], -1)
    P[1, 1, :2] += [0.2 * half, -0.1 * half]
    P[2, 1, :2] += [0.1 * half, 0.15 * half]
    P[1, 2, :2] += [-0.15 * half, 0.1 * half]
    return core.NurbsSurface(P, np.ones((4, 4)), 4, 4, KNOTS4, KNOTS4)


def bumpy_nurbs(seed=0):
    """A bicubic height field with an interior knot at 0.5 in both directions (C2 across it)."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.linspace(-1, 1, 5), np.linspace(-1, 1, 5), indexing="ij")
    z = 0.3 * rng.standard_normal((5, 5))
    knots = [0, 0, 0, 0, 0.5, 1, 1, 1, 1]
    return core.NurbsSurface(np.stack([i, j, z], -1), np.ones((5, 5)), 4, 4, knots, knots)


def twisted_quad(h=0.4):
    return core.Quad((-1, -1, -h), (1, -1, h), (1, 1, -h), (-1, 1, h))


def points_facing(rng, count, center, normal, distance, spread=0.6):
    """Points on the front side of a patch (centre, front normal) and unit normals roughly
    toward it, shapes (count, 3)."""
    d = rng.normal(size=(count, 3)) * spread + normal
    d /= np.linalg.norm(d, axis=1)[:, None]
    x = center + d * rng.uniform(*distance, size=(count, 1))
    n = -d + rng.normal(size=(count, 3)) * spread
    n /= np.linalg.norm(n, axis=1)[:, None]
    return x, n


def inner_values(surfaces, x, n, target, tol=1e-11):
    """F(dA -> surfaces[target]) by the solver's inner integral, with its error estimates."""
    solver = FormFactorSolver(surfaces)
    patch = np.full(len(x), target)
    F, error, _ = solver.inner(x, n, patch, np.full(len(x), tol))
    return F, error, solver


def test_flat_nurbs_square_against_polygon():
    """A NURBS square (generic: contoured cells and line rule) equals the exact polygon value."""
    rng = np.random.default_rng(1)
    x, n = points_facing(rng, 40, np.zeros(3), np.array([0.0, 0.0, 1.0]), (0.3, 3.0))
    square = core.Quad((-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0))
    nurbs = flat_nurbs_square()
    F, error, solver = inner_values([nurbs, square], x, n, 0)
    assert solver.inner.kind[0] == GENERIC and solver.inner.kind[1] == POLYGON
    exact, _, _ = solver.inner(x, n, np.ones(len(x), dtype=int), np.full(len(x), 1e-12))
    assert (exact > 0).sum() >= 30
    # (at tol 1e-11 the line-rule cells alone, contour off, miss by the same 1.45e-10 at two
    # points: the line rule's own estimate, not the contour's)
    assert np.abs(F - exact).max() <= 2e-10 + error.max()
    assert solver.inner.edges.size > 0  # the contour took part


def test_whole_patch_contour_is_the_polygon_value():
    """contour_rule on the whole flat NURBS square, from points that see it wholly, front on."""
    nurbs = flat_nurbs_square()
    solver = FormFactorSolver([nurbs])
    edges = solver.inner.edges
    rng = np.random.default_rng(2)
    x = np.c_[rng.uniform(-0.5, 0.5, (30, 2)), rng.uniform(2.0, 4.0, 30)]
    n = np.tile([0.0, 0.0, -1.0], (30, 1)) + rng.normal(size=(30, 3)) * 0.05
    n /= np.linalg.norm(n, axis=1)[:, None]
    zero = np.zeros(30, dtype=np.int64)
    rows = edges.lookup(zero, zero, zero, zero, zero)
    value, error = contour_rule(x, n, edges.points[rows], edges.steps[rows])
    square = core.Quad((-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0))
    exact, _, _ = inner_values([square], x, n, 0)
    assert np.abs(value - exact).max() <= 1e-13
    assert (error <= 1e-12).all() and edges.points.shape[1] == NODES


def test_nurbs_sphere_octant_against_exact_sphere_patch():
    """An exact rational NURBS octant (its pole edge has zero length) against the sphere-patch
    closed form of the same octant."""
    octant = nurbs_sphere(1.0).subpatch(u=(0.0, 0.25), v=(0.5, 1.0))
    exact_octant = core.Sphere((0, 0, 0), 1.0).subpatch(u=(0.0, np.pi / 2), v=(0.0, np.pi / 2))
    rng = np.random.default_rng(3)
    x, n = points_facing(rng, 40, np.full(3, 1 / np.sqrt(3)), np.full(3, 1 / np.sqrt(3)), (0.3, 3.0))
    F, error, solver = inner_values([octant, exact_octant], x, n, 0)
    assert solver.inner.kind[0] == GENERIC and solver.inner.kind[1] != GENERIC
    exact, _, _ = solver.inner(x, n, np.ones(len(x), dtype=int), np.full(len(x), 1e-12))
    assert (exact > 0).any()
    assert np.abs(F - exact).max() <= 1e-10 + error.max()


@pytest.mark.parametrize("make", [twisted_quad, bumpy_nurbs], ids=["twisted_quad", "nurbs_knots"])
def test_contour_against_line_rule(make, monkeypatch):
    """Random points and orientations: the inner integral with contoured cells equals the line
    rule alone (contour off) within their error estimates."""
    surface = make()
    rng = np.random.default_rng(4)
    x, n = points_facing(rng, 40, np.zeros(3), np.array([0.0, 0.0, 1.0]), (0.5, 3.0), spread=0.8)
    F, error, solver = inner_values([surface], x, n, 0, tol=1e-10)
    assert solver.inner.kind[0] == GENERIC
    contoured = solver.inner.edges.size
    assert contoured > 0  # the contour took part
    monkeypatch.setattr(inner_module, "CONTOUR_GAP", np.inf)
    G, error_g, solver_g = inner_values([surface], x, n, 0, tol=1e-10)
    assert solver_g.inner.edges.size == 0
    assert np.abs(F - G).max() <= 3e-10 + (error + error_g).max()


def test_similarity_and_mirror_invariance():
    """F(dA -> patch) is unchanged when point and patch move by one similarity map, and when
    both are mirrored (the mirrored patch's boundary runs the other way about its front)."""
    surface = bumpy_nurbs(1)
    rng = np.random.default_rng(5)
    x, n = points_facing(rng, 20, np.zeros(3), np.array([0.0, 0.0, 1.0]), (0.8, 3.0), spread=0.5)
    F, error, _ = inner_values([surface], x, n, 0, tol=1e-11)
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    for linear in (3.7 * q, np.diag([1.0, 1.0, -1.0]) @ q * 0.25):
        M = np.eye(4)
        M[:3, :3] = linear
        M[:3, 3] = [100.0, -40.0, 7.0]
        moved = surface.transformed(M)
        nx = n @ linear.T
        nx /= np.linalg.norm(nx, axis=1)[:, None]
        G, error_g, _ = inner_values([moved], x @ linear.T + M[:3, 3], nx, 0, tol=1e-11)
        assert np.abs(F - G).max() <= 1e-10 + (error + error_g).max()


def test_no_contour_across_knots():
    """Cells straddling an interior knot line are not contoured; cells inside one span are."""
    surface = bumpy_nurbs(2)
    solver = FormFactorSolver([surface])
    x = np.array([[0.0, 0.0, 30.0]])
    n = np.array([[0.0, 0.0, -1.0]])
    cells = CellBatch(
        np.zeros(3, dtype=np.int64),
        np.array([0, 1, 3]),
        np.array([0, 1, 3]),
        np.array([0, 0, 1]),
        np.array([0, 0, 1]),
    )
    value, extra, forced, _, contoured = solver.inner._rule_cells(
        cells, x, n, np.zeros(1, dtype=int), np.zeros(1, dtype=bool)
    )
    assert not contoured[0]  # the root holds the knot lines u = v = 0.5
    assert contoured[1] and contoured[2]  # a quarter and a sixteenth lie within one span
    assert (forced[contoured] == SPLIT_NONE).all() and (value > 0).all()


def test_final_cells_are_not_refined():
    """A final cell's halves are never evaluated and the item's value is its value."""
    seen = []

    def evaluate(cells):
        seen.append(cells.level.copy())
        value = 0.5 ** (cells.lu + cells.lv)
        size = value.size
        return value, np.full(size, 1e-15), np.zeros(size, np.int8), size, np.ones(size, bool)

    value, error, _ = integrate_cells(evaluate, 3, np.full(3, 1e-30))
    assert len(seen) == 1 and (np.concatenate(seen) == 0).all()
    assert np.allclose(value, 1.0) and np.allclose(error, 1e-15)


def test_quadpack_error():
    """The estimate shrinks a small difference (the finer rule converges faster) but not below
    rounding, and keeps a large one."""
    assert quadpack_error(np.array([1e-2]), np.array([1.0]))[0] == pytest.approx(1e-2)
    small = quadpack_error(np.array([1e-9]), np.array([1.0]))[0]
    assert 50 * np.finfo(float).eps <= small < 1e-9
