"""Linear solvers for the radiosity system B = E + rho * (F B), per colour channel.

F is given sparse, as (row, col, value) triples of the pairs that were computed. Small systems
are solved directly (dense LU); large ones by Jacobi sweeps (one sweep = one more bounce of
light), stopped by an error bound: with contraction q = max_i rho_i sum_j F_ij < 1, the error
after a sweep that changed B by delta is at most q / (1 - q) * |delta|.
"""

import numpy as np

DIRECT_LIMIT = 2500  # elements up to which the system is solved densely
MAX_SWEEPS = 100_000


def solve(rows, cols, values, rho, E, tol, max_bounces=None, method=None, cancel=None):
    """Solve B = E + rho * (F B) for B, shape (N, 3).

    Parameters
    ----------
    rows, cols : ndarray of int, shape (P,)
    values : ndarray, shape (P,)
        F[rows, cols] (pairs not listed are zero).
    rho, E : ndarray, shape (N, 3)
    tol : float
        Relative accuracy of B (iterative method).
    max_bounces : int or None
        Stop after this many bounces (Jacobi sweeps from B = E); None: to convergence.
    method : {None, "direct", "iterative"}
        None chooses: direct up to DIRECT_LIMIT elements unless max_bounces is given.
    cancel : callable() -> bool or None
        Checked between sweeps; when it returns True, `Cancelled` is raised by the caller's hook.

    Returns
    -------
    B : ndarray, shape (N, 3)
    info : dict
        "method", "iterations", "residual" (max-norm of E + rho F B - B over max |B|),
        "contraction" (q).
    """
    N = len(E)
    row_sum = np.bincount(rows, weights=values, minlength=N)
    q = float(np.max(rho.max(1) * row_sum)) if N else 0.0
    if method is None:
        method = "direct" if (max_bounces is None and N <= DIRECT_LIMIT) else "iterative"
    if method == "direct":
        F = np.zeros((N, N))
        np.add.at(F, (rows, cols), values)
        B = np.empty_like(E)
        for c in range(3):
            A = np.eye(N) - rho[:, c, None] * F
            B[:, c] = np.linalg.solve(A, E[:, c])
        iterations = 0
    else:
        B, iterations = _jacobi(rows, cols, values, rho, E, tol, q, max_bounces, cancel)
    residual = E + rho * _apply(rows, cols, values, B) - B
    scale = max(float(np.abs(B).max()), 1e-300)
    info = dict(
        method=method, iterations=iterations, residual=float(np.abs(residual).max() / scale), contraction=q
    )
    return B, info


def _apply(rows, cols, values, B):
    """F B for sparse F, shape (N, 3)."""
    out = np.empty_like(B)
    for c in range(3):
        out[:, c] = np.bincount(rows, weights=values * B[cols, c], minlength=len(B))
    return out


def _jacobi(rows, cols, values, rho, E, tol, q, max_bounces, cancel):
    B = E.copy()
    limit = MAX_SWEEPS if max_bounces is None else int(max_bounces)
    factor = q / (1.0 - q) if q < 1.0 else np.inf
    for sweep in range(1, limit + 1):
        new = E + rho * _apply(rows, cols, values, B)
        change = float(np.abs(new - B).max())
        B = new
        if cancel is not None:
            cancel()
        if max_bounces is None and (
            change * min(factor, 1e6) <= tol * max(float(np.abs(B).max()), 1e-300) or change == 0
        ):
            return B, sweep
    return B, limit if max_bounces is not None else MAX_SWEEPS
