"""Radiosity solvers: every element meets tol relative to its own radiosity, whatever the method;
bounce limits; near-singular systems; no silent wrong value."""

import numpy as np
import pytest
from test_scene import room

import core
from core import solvers


def random_system(seed, N=600, density=0.05, emitters=6, rho_max=0.95):
    """A random sparse F >= 0 with row sums in (0.3, 1), reflectances in [0, rho_max] and a few
    emitters, so most elements are lit only through others and some are very dark.

    Returns rows, cols, values, rho (N, 3), E (N, 3).
    """
    rng = np.random.default_rng(seed)
    mask = rng.random((N, N)) < density
    np.fill_diagonal(mask, False)
    rows, cols = np.nonzero(mask)
    values = rng.random(rows.size) ** 4  # a wide spread of factors
    sums = np.bincount(rows, weights=values, minlength=N)
    target = rng.uniform(0.3, 1.0, N)
    values = values * (target / np.where(sums > 0, sums, 1.0))[rows]
    rho = rng.uniform(0.0, rho_max, (N, 3))
    E = np.zeros((N, 3))
    E[rng.choice(N, emitters, replace=False)] = rng.uniform(1.0, 50.0, (emitters, 3))
    return rows, cols, values, rho, E


def exact(rows, cols, values, rho, E):
    """B = (I - rho F)^-1 E per channel by dense LU (numpy's gesv), shape (N, 3)."""
    N = len(E)
    F = np.zeros((N, N))
    F[rows, cols] = values
    return np.stack([np.linalg.solve(np.eye(N) - rho[:, c, None] * F, E[:, c]) for c in range(3)], 1)


def worst_relative(B, reference):
    """max_i |B_i - B*_i| / B*_i over elements and channels (B* > 0 everywhere it is used)."""
    return float((np.abs(B - reference) / reference).max())


# ------------------------------------------------------------------- random sparse systems
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("method", [None, "jacobi"])
@pytest.mark.parametrize("tol", [1e-2, 1e-4])
def test_random_sparse_matches_direct_per_element(seed, method, tol):
    """Above DIRECT_SOLVE_LIMIT elements the iterative result equals (I - rho F)^-1 E to tol
    relative to each element's own B, the darkest included."""
    rows, cols, values, rho, E = random_system(seed)
    reference = exact(rows, cols, values, rho, E)
    kwargs = dict(max_bounces=solvers.SWEEP_BUDGET) if method == "jacobi" else {}
    B, info = solvers.solve(rows, cols, values, rho, E, tol, method=method, **kwargs)
    # the test covers what it claims: an iterative solve, elements far darker than the brightest
    assert info["method"] == ("jacobi" if method else "gmres"), (seed, info)
    darkest = reference.min() / reference.max()
    assert darkest < 1e-3, f"seed {seed}: darkest element at {darkest:.2e} of the brightest"
    error = worst_relative(B, reference)
    assert error <= tol, f"seed {seed}: worst per-element error {error:.3e} > tol {tol}"
    assert info["error_bound"] <= tol * (1 + 1e-9), info
    assert info["error_bound"] >= error * (1 - 1e-6), (
        f"the bound {info['error_bound']} is not a bound ({error})"
    )


def test_old_rule_would_fail_on_the_dark_elements():
    """The stop rule relative to the brightest element, q/(1-q) max|dB| <= tol max|B|, leaves
    dark elements far off tol: the per-element rule does not (same system, same tol)."""
    rows, cols, values, rho, E = random_system(0)
    reference = exact(rows, cols, values, rho, E)
    tol = 1e-3
    N = len(E)
    q = float((rho.max(1) * np.bincount(rows, weights=values, minlength=N)).max())
    B = E.copy()
    while True:
        new = E + rho * np.stack(
            [np.bincount(rows, weights=values * B[cols, c], minlength=N) for c in range(3)], 1
        )
        change, B = np.abs(new - B).max(), new
        if q / (1 - q) * change <= tol * np.abs(B).max():
            break
    assert worst_relative(B, reference) > 10 * tol
    B, _ = solvers.solve(rows, cols, values, rho, E, tol, method="jacobi", max_bounces=solvers.SWEEP_BUDGET)
    assert worst_relative(B, reference) <= tol


def test_sparse_products_give_the_same_result(monkeypatch):
    """Above DENSE_MATRIX_LIMIT products go through the sparse triples; results agree to tol."""
    rows, cols, values, rho, E = random_system(3, N=450)
    reference = exact(rows, cols, values, rho, E)
    monkeypatch.setattr(solvers, "DENSE_MATRIX_LIMIT", 100)
    for method in ("iterative", "jacobi"):
        kwargs = dict(max_bounces=solvers.SWEEP_BUDGET) if method == "jacobi" else {}
        B, info = solvers.solve(rows, cols, values, rho, E, 1e-5, method=method, **kwargs)
        assert worst_relative(B, reference) <= 1e-5, (method, info)


def test_a_row_summing_above_one_keeps_a_bound():
    """Quadrature error can let a row sum above 1 (q > 1); the bound through ||(rho F)^2|| < 1
    still holds, so GMRES stops on it and meets tol (no fallback)."""
    rows, cols, values, rho, E = random_system(9, N=450)
    values = np.where(rows == 0, values * 1.2 / values[rows == 0].sum(), values)
    rho[0] = 0.95
    reference = exact(rows, cols, values, rho, E)
    B, info = solvers.solve(rows, cols, values, rho, E, 1e-4)
    assert info["contraction"] > 1 and info["method"] == "gmres" and info["fallback"] is None, info
    assert worst_relative(B, reference) <= 1e-4


# ----------------------------------------------------------------------------- bounces
def test_bounces_are_jacobi_sweeps():
    """max_bounces=n gives sum_{k<=n} (rho F)^k E exactly (n = 0, 1, 3)."""
    rows, cols, values, rho, E = random_system(4, N=120)
    N = len(E)
    F = np.zeros((N, N))
    F[rows, cols] = values
    expected = E.copy()
    term = E.copy()
    for n in range(4):
        if n:
            term = rho * (F @ term)
            expected = expected + term
        if n in (0, 1, 3):
            B, info = solvers.solve(rows, cols, values, rho, E, 1e-6, max_bounces=n)
            np.testing.assert_allclose(B, expected, rtol=1e-12, atol=1e-14 * E.max())
            assert info["method"] == "jacobi" and info["iterations"] == n


def test_bounces_stop_at_convergence():
    """A bounce count larger than convergence needs stops early, at the converged B."""
    rows, cols, values, rho, E = random_system(5, N=300, rho_max=0.6)
    reference = exact(rows, cols, values, rho, E)
    B, info = solvers.solve(rows, cols, values, rho, E, 1e-4, max_bounces=5000)
    assert info["iterations"] < 200, info
    assert worst_relative(B, reference) <= 1e-4


@pytest.mark.parametrize("bounces", [10**6, 10**9, 10**18])
def test_absurd_bounce_counts_return_the_converged_result(bounces):
    """n bounces beyond the sweep budget: (rho F)^(n+1) B* <= s q^n max B* is negligible, so the
    converged B is the answer, found without n sweeps (no hang)."""
    rows, cols, values, rho, E = random_system(6, N=500)
    reference = exact(rows, cols, values, rho, E)
    B, info = solvers.solve(rows, cols, values, rho, E, 1e-4, max_bounces=bounces)
    assert worst_relative(B, reference) <= 1e-4
    assert info["iterations"] < 1000, info


def test_bounce_count_that_cannot_converge_is_refused():
    """q = 0.99999 and n = 20,000 bounces: B_n is far from B* (q^n ~ 0.8) and n sweeps exceed
    the budget: a ValueError names the problem instead of a long hang or a wrong value."""
    F = np.full((30, 30), 1.0 / 30)
    rows, cols = np.nonzero(F > 0)
    rho = np.full((30, 3), 0.99999)
    E = np.ones((30, 3))
    with pytest.raises(ValueError, match="max_bounces=20000"):
        solvers.solve(rows, cols, F[rows, cols], rho, E, 1e-3, max_bounces=20_000)


# ------------------------------------------------------------------ nearly singular systems
def test_budget_exhausted_falls_back_to_direct_or_raises(monkeypatch):
    """A GMRES solve that runs out of budget is replaced by the dense direct solve (and says so);
    where no dense matrix may be built it raises ConvergenceError with the residual reached."""
    rows, cols, values, rho, E = random_system(7, N=450, rho_max=0.999)
    reference = exact(rows, cols, values, rho, E)
    monkeypatch.setattr(solvers, "KRYLOV_BUDGET", 3)
    B, info = solvers.solve(rows, cols, values, rho, E, 1e-6)
    assert info["method"] == "direct" and "GMRES did not converge" in info["fallback"]
    assert worst_relative(B, reference) <= 1e-9
    monkeypatch.setattr(solvers, "DENSE_MATRIX_LIMIT", 100)
    with pytest.raises(solvers.ConvergenceError, match="relative residual") as failure:
        solvers.solve(rows, cols, values, rho, E, 1e-6)
    assert failure.value.residual > failure.value.goal > 0
    assert isinstance(failure.value, ValueError)


def test_singular_system_raises():
    """rho = 1 in a closed two-element room: I - rho F is singular, no steady state."""
    rows, cols, values = np.array([0, 1]), np.array([1, 0]), np.array([1.0, 1.0])
    rho = np.ones((2, 3))
    E = np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    for method in (None, "iterative"):
        with pytest.raises(ValueError, match="singular"):
            solvers.solve(rows, cols, values, rho, E, 1e-3, method=method)


@pytest.mark.parametrize("method, bounces", [("iterative", None), ("jacobi", 50)])
def test_cancel_is_polled_between_products(method, bounces):
    """The cancel callback runs between products with F, and what it raises stops the solve."""
    rows, cols, values, rho, E = random_system(10, N=450)
    calls = []

    class StopError(Exception):
        pass

    def cancel():
        calls.append(1)
        if len(calls) == 3:
            raise StopError

    with pytest.raises(StopError):
        solvers.solve(rows, cols, values, rho, E, 1e-6, method=method, max_bounces=bounces, cancel=cancel)
    assert len(calls) == 3


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(values=-1.0), "non-negative"),
        (dict(rho=1.5), "reflectance"),
        (dict(E=np.nan), "emission"),
        (dict(tol=0.0), "tol"),
        (dict(method="lu"), "method"),
        (dict(method="direct", max_bounces=2), "max_bounces"),
        (dict(max_bounces=-1), "max_bounces"),
        (dict(max_bounces=1.5), "max_bounces"),
        (dict(max_bounces=float("inf")), "max_bounces"),
        (dict(max_bounces="3"), "max_bounces"),
        (dict(max_bounces=True), "max_bounces"),
        (dict(rows=99), "indices"),
    ],
)
def test_bad_input(change, message):
    rows, cols, values, rho, E = random_system(8, N=20, density=0.3)
    args = dict(rows=rows, cols=cols, values=values, rho=rho, E=E, tol=1e-3)
    for key, value in change.items():
        if key in ("values", "rho", "E", "rows"):  # one bad entry in an array
            args[key] = args[key].copy()
            args[key][0] = value
        else:
            args[key] = value
    with pytest.raises(ValueError, match=message):
        solvers.solve(**args)


# --------------------------------------------------------------------- through core.Scene
def closed_box(n, rho, emission):
    """Six inward walls of the unit cube, n x n patches each (6 n^2 elements)."""
    scene = core.Scene()
    walls = [scene.add(w, patches=(n, n), reflectance=rho, emission=e) for w, e in zip(room(), emission)]
    return scene, walls


def radiosities(sol, handles):
    return np.concatenate([sol.radiosity(h) for h in handles])


def test_white_furnace_near_one():
    """Closed cube, uniform E, rho = 0.999 and 0.99999, 486 elements (GMRES): B = E / (1 - rho).

    With the computed rows summing to 1 - delta_i, the maximum principle bounds every element
    between E / (1 - rho (1 - max delta)) and E / (1 - rho (1 - min delta)); at tol 1e-6 delta
    is ~1e-10, so the analytic value holds to ~1e-5 even at rho = 0.99999.
    """
    scene, walls = closed_box(9, 0.5, [1.0] * 6)
    tol = 1e-6
    for rho in (0.999, 0.99999):
        for h in walls:
            scene.set_material(h, reflectance=rho)
        sol = scene.solve(tol=tol)
        assert sol.stats["elements"] == 486 and sol.stats["solver"] == "gmres", sol.stats
        delta = 1.0 - sol.form_factor_matrix().sum(1)
        low, high = 1.0 / (1 - rho * (1 - delta.max())), 1.0 / (1 - rho * (1 - delta.min()))
        B = radiosities(sol, walls)
        assert np.all(B >= low * (1 - tol)) and np.all(B <= high * (1 + tol)), (
            rho,
            B.min(),
            B.max(),
            low,
            high,
        )
        assert np.abs(B * (1 - rho) - 1).max() < 1e-4


def test_closed_cube_near_one_with_one_emitting_wall():
    """rho = 0.99999, only the floor emits: the iterative solve equals the direct one per element
    to tol, and absorbed power equals emitted power to the rows' accuracy."""
    scene, walls = closed_box(9, 0.99999, [1.0, 0, 0, 0, 0, 0])
    tol = 1e-4
    sol = scene.solve(tol=tol)
    assert sol.stats["solver"] == "gmres"
    direct = scene.solve(tol=tol, method="direct")
    assert direct.stats["solver"] == "direct"
    B, reference = radiosities(sol, walls), radiosities(direct, walls)
    assert worst_relative(B, reference) <= tol
    # a billion bounces: the converged answer, without a billion sweeps
    endless = scene.solve(tol=tol, max_bounces=10**9)
    assert worst_relative(radiosities(endless, walls), reference) <= tol
    assert endless.stats["iterations"] < 1000, endless.stats
    A = sol.element_areas()
    emitted = A[:81].sum()
    absorbed = float((A * (1 - 0.99999) * B[:, 0]).sum())
    delta = np.abs(1.0 - sol.form_factor_matrix().sum(1)).max()
    assert abs(absorbed / emitted - 1) <= tol + 2 * delta / (1 - 0.99999)


def test_dark_indirectly_lit_elements_meet_tol():
    """Box of 9 x 9 walls and a small down-facing lamp under the ceiling (490 elements): the
    ceiling, black-ish (rho 0.02) and lit only by the walls, meets tol relative to its own B."""
    scene = core.Scene()
    materials = [0.7, 0.02, 0.7, 0.7, 0.7, 0.7]  # floor, ceiling, walls
    walls = [scene.add(w, patches=(9, 9), reflectance=r) for w, r in zip(room(), materials)]
    z = 0.999
    scene.add(
        core.Quad((0.4, 0.4, z), (0.6, 0.4, z), (0.6, 0.6, z), (0.4, 0.6, z)).flipped(),
        emission=50.0,
        reflectance=0.0,
        patches=(2, 2),
        occluder=False,
    )
    tol = 1e-3
    sol = scene.solve(tol=tol)
    assert sol.stats["elements"] == 490 and sol.stats["solver"] == "gmres", sol.stats
    reference = radiosities(scene.solve(tol=tol, method="direct"), walls)
    B = radiosities(sol, walls)
    ceiling = reference[81:162]
    assert ceiling.max() < 2e-3 * 50.0, "the ceiling should be dark next to the lamp"
    assert worst_relative(B, reference) <= tol
    assert sol.stats["error_bound"] <= tol
