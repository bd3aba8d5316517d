"""Linear solvers for the radiosity system B = E + rho * (F B), per colour channel.

F is given sparse, as (row, col, value) triples of the pairs that were computed (and dense for
small scenes). Up to DENSE_ITERATIVE_FROM elements the system is solved directly (dense LU, one
per channel); larger ones by Jacobi sweeps (one sweep = one more bounce of light; dense products
up to DIRECT_LIMIT elements, sparse ones beyond), stopped by an error bound: with contraction
q = max_i rho_i sum_j F_ij < 1, the error after a sweep that changed B by delta is at most
q / (1 - q) * |delta|.
"""

import numpy as np

DIRECT_LIMIT = 2500  # elements up to which F is also kept dense (fast products)
DENSE_ITERATIVE_FROM = 400  # above this many elements, Jacobi sweeps beat an LU factorisation
MAX_SWEEPS = 100_000


def solve(rows, cols, values, rho, E, tol, max_bounces=None, method=None, cancel=None, dense=None):
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
    cancel : callable() or None
        Called between sweeps (it raises to stop).
    dense : ndarray, shape (N, N), optional
        The same F as a dense matrix (small scenes): products with it are much faster.

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
        method = "direct" if (max_bounces is None and N <= DENSE_ITERATIVE_FROM) else "iterative"
    if method not in ("direct", "iterative"):
        raise ValueError(f'method must be None, "direct" or "iterative", got {method!r}')
    if dense is None and (method == "direct" or N <= DIRECT_LIMIT):
        dense = np.zeros((N, N))
        np.add.at(dense, (rows, cols), values)
    if method == "direct":
        F = dense
        B = np.empty_like(E)
        for c in range(3):
            A = np.eye(N) - rho[:, c, None] * F
            B[:, c] = np.linalg.solve(A, E[:, c])
        iterations = 0
    else:
        B, iterations = _jacobi(rows, cols, values, rho, E, tol, q, max_bounces, cancel, dense)
    residual = E + rho * _apply(rows, cols, values, B, dense) - B
    scale = max(float(np.abs(B).max()), 1e-300)
    info = dict(
        method=method, iterations=iterations, residual=float(np.abs(residual).max() / scale), contraction=q
    )
    return B, info


def _apply(rows, cols, values, B, dense=None):
    """F B, shape (N, 3), from the dense F when there is one."""
    if dense is not None:
        return dense @ B
    out = np.empty_like(B)
    for c in range(3):
        out[:, c] = np.bincount(rows, weights=values * B[cols, c], minlength=len(B))
    return out


def _jacobi(rows, cols, values, rho, E, tol, q, max_bounces, cancel, dense=None):
    B = E.copy()
    limit = MAX_SWEEPS if max_bounces is None else int(max_bounces)
    factor = q / (1.0 - q) if q < 1.0 else np.inf
    for sweep in range(1, limit + 1):
        new = E + rho * _apply(rows, cols, values, B, dense)
        change = float(np.abs(new - B).max())
        B = new
        if cancel is not None:
            cancel()
        if max_bounces is None and (
            change * min(factor, 1e6) <= tol * max(float(np.abs(B).max()), 1e-300) or change == 0
        ):
            return B, sweep
    return B, limit if max_bounces is not None else MAX_SWEEPS
