"""Linear solvers for the radiosity system B = E + rho * (F B), per colour channel.

F is given sparse, as (row, col, value) triples of the pairs that were computed (and dense for
scenes up to DENSE_MATRIX_LIMIT elements). Three methods:

- "direct": dense LU, one per channel (up to DIRECT_SOLVE_LIMIT elements by default);
- "gmres": restarted GMRES (Saad & Schultz 1986) on (I - rho F) B = E, the default above
  DIRECT_SOLVE_LIMIT elements;
- "jacobi": sweeps B <- E + rho F B from B = E, one bounce of light each; used for
  `max_bounces=n` (n bounces of light are n sweeps).

Every method ends with one sweep B' = E + rho F B and stops on the same per-element bound. With
B* the solution, r = B' - B (the residual of B), s = rho F 1 (s_i = rho_i sum_j F_ij), q = max_i s_i
and q2 = max_i (rho F s)_i = ||(rho F)^2||_inf (per channel; F >= 0): when q2 < 1 the Neumann
series gives (I - rho F)^-1 = (I + rho F) sum_k (rho F)^2k >= 0 with
||(I - rho F)^-1||_inf <= kappa = (1 + q) / (1 - q2) (<= 1 / (1 - q) when q < 1, and finite where
quadrature error lets a few rows sum above 1). B - B* = -(I - rho F)^-1 r and
B' - B* = rho F (B - B*) give, for every element i,

    |B'_i - B*_i| <= s_i kappa ||r||_inf.

A solve stops when this bound is at most tol * max(B'_i, FLOOR * max_k B'_k) for every element
and channel: dark and indirectly lit elements are held to tol relative to their own radiosity, not
the lamp's (B'_i >= rho_i (F B)_i, so an element that reflects little is also held to tol of the
light it receives; only elements darker than FLOOR times the brightest get an absolute floor). The
residual asked for is never below ROUNDING * max B (what double precision can reach); the bound
reached is returned as info["error_bound"]. If an iterative solve cannot reach its goal within
its budget it falls back to the direct solve where F is dense, and otherwise raises `ConvergenceError`.
"""

import numpy as np

from .checks import ArgumentTypeError

DENSE_MATRIX_LIMIT = 2500  # elements up to which F is also kept as a dense matrix (fast products)
DIRECT_SOLVE_LIMIT = 400  # elements up to which the default solve is dense LU
KRYLOV_BUDGET = 2000  # products with F a GMRES solve may take before it gives up
SWEEP_BUDGET = 10_000  # Jacobi sweeps (bounces) a bounce-limited solve may take
RESTART = 40  # GMRES restart length (Krylov vectors kept)
FLOOR = 1e-9  # elements darker than this fraction of the brightest are held to tol * FLOOR * max B
ROUNDING = 1e-13  # smallest residual asked for, relative to max B (double-precision rounding)
OVERFULL_ROW = 1e-2  # a patch's form factors summing above 1 by more than this are named in errors
DIVERGENCE_SWEEPS = 30  # a residual no smaller than this many sweeps before: the sweeps diverge


class CrossingSurfaceError(ValueError):
    """A solve refused because some surfaces' patches see more than their whole hemisphere: a
    patch's form factors summing above 1 (by more than OVERFULL_ROW) with occlusion on, which
    happens where a surface passes through itself or through another (each side sees the other
    side of the crossing; e.g. a NURBS net that its cyclic flags fold onto itself, its layers
    coinciding, which no ray can tell apart).

    Attributes
    ----------
    handles : tuple of int
        Those surfaces' handles (`Scene.add`; in the hierarchy, its object indices).
    row_sums : tuple of float
        Each one's largest patch row sum.
    """

    def __init__(self, message, handles, row_sums):
        super().__init__(message)
        self.handles = tuple(handles)
        self.row_sums = tuple(row_sums)


class ConvergenceError(ValueError):
    """An iterative radiosity solve did not reach its accuracy goal within its budget.

    Attributes
    ----------
    residual : float
        max |E + rho F B - B| reached, relative to max |B|.
    goal : float
        The residual that was needed, on the same scale.
    iterations : int
        Products with F (or sweeps) spent.
    """

    def __init__(self, message, residual, goal, iterations):
        super().__init__(message)
        self.residual = residual
        self.goal = goal
        self.iterations = iterations


def solve(rows, cols, values, rho, E, tol, max_bounces=None, method=None, cancel=None, dense=None):
    """Solve B = E + rho * (F B) for B, shape (N, 3), to a per-element relative accuracy.

    Parameters
    ----------
    rows, cols : ndarray of int, shape (P,)
    values : ndarray, shape (P,)
        F[rows, cols] >= 0 (pairs not listed are zero; each ordered pair listed once).
    rho, E : ndarray, shape (N, 3)
        Reflectance in [0, 1] and emission >= 0, per element and channel.
    tol : float
        Relative accuracy of every element's B (see the module docstring for the bound used).
    max_bounces : int or None
        Follow at most this many bounces of light (Jacobi sweeps from B = E), stopping earlier
        when converged; None: to convergence. Values beyond SWEEP_BUDGET give the converged B if
        that many bounces provably reach it to tol, and raise a ValueError otherwise.
    method : {None, "direct", "iterative", "gmres", "jacobi"}
        None chooses: "direct" up to DIRECT_SOLVE_LIMIT elements, "gmres" ("iterative") above,
        "jacobi" when max_bounces is given.
    cancel : callable() or None
        Called between products with F (it raises to stop).
    dense : ndarray, shape (N, N), optional
        The same F as a dense matrix: products with it are much faster. Built here when the
        direct solve needs it or N <= DENSE_MATRIX_LIMIT.

    Returns
    -------
    B : ndarray, shape (N, 3)
    info : dict
        "method" ("direct", "gmres" or "jacobi"), "iterations" (products with F: sweeps for
        Jacobi, Krylov steps for GMRES, 0 for direct), "residual" (max-norm of E + rho F B - B of
        the iterate before the final sweep, over max |B|), "error_bound" (max over elements and
        channels of the bound on |B_i - B*_i| over max(B_i, FLOOR max B); inf when
        ||(rho F)^2||_inf >= 1 leaves no bound),
        "contraction" (q, max over channels), "fallback" (why a direct solve replaced an
        iterative one, or None).

    Raises
    ------
    ValueError
        Bad input; a singular system (LU failure or a clearly negative B); max_bounces with
        method "direct" or "gmres"; a bounce count beyond SWEEP_BUDGET that does not provably
        reach the converged B.
    ConvergenceError
        An iterative solve that reached neither its goal nor a direct fallback.
    """
    # check the inputs: a wrong shape or a negative factor would void the error bound
    rows, cols, values, rho, E, tol = _checked(rows, cols, values, rho, E, tol)
    if method not in (None, "direct", "iterative", "gmres", "jacobi"):
        raise ValueError(f'method must be None, "direct", "iterative", "gmres" or "jacobi", got {method!r}')
    max_bounces = bounce_count(max_bounces)
    N = len(E)
    if N == 0:
        return E.copy(), dict(
            method="direct", iterations=0, residual=0.0, error_bound=0.0, contraction=0.0, fallback=None
        )
    system = _System(rows, cols, values, rho, E, tol, dense)

    # choose the method: bounces are Jacobi sweeps; else LU for small systems, GMRES above
    if max_bounces is not None:
        if method not in (None, "iterative", "jacobi"):
            raise ValueError(f'max_bounces counts Jacobi sweeps: use method None or "jacobi", got {method!r}')
        method = "jacobi"
    elif method is None:
        method = "direct" if N <= DIRECT_SOLVE_LIMIT else "gmres"
    elif method == "iterative":
        method = "gmres"
    fallback = None

    # solve; a bounce-limited solve beyond the sweep budget must converge within its bounces
    if max_bounces is not None and int(max_bounces) > SWEEP_BUDGET:
        B, iterations, method = _converged_within(system, int(max_bounces), cancel)
    elif method == "jacobi":
        B, iterations = _jacobi(system, max_bounces, cancel)
    elif method == "gmres":
        try:
            B, iterations = _gmres(system, cancel)
        except ConvergenceError as failure:
            if system.dense is None:  # above DENSE_MATRIX_LIMIT: no dense LU unless asked for
                raise
            fallback = str(failure)
            B, iterations, method = _direct(system), failure.iterations, "direct"
    else:
        B, iterations = _direct(system), 0

    # one final sweep: the bound holds for B' = E + rho F B
    B_final, residual = system.sweep(B)
    B_final = np.maximum(B_final, 0.0)  # B* >= 0: clipping only moves B' closer to it
    bound = system.relative_bound(B_final, residual)
    scale = max(float(np.abs(B_final).max()), 1e-300)
    info = dict(
        method=method,
        iterations=int(iterations),
        residual=float(np.abs(residual).max() / scale),
        error_bound=float(bound),
        contraction=float(system.q.max()),
        fallback=fallback,
    )
    return B_final, info


def bounce_count(max_bounces):
    """`max_bounces` as an int (or None), or a ValueError: a non-negative integer is required.

    Parameters
    ----------
    max_bounces : int, integral float or None

    Returns
    -------
    int or None
    """
    if max_bounces is None:
        return None
    if isinstance(max_bounces, (str, bytes, bool, np.bool_)):
        raise ArgumentTypeError(f"max_bounces must be a non-negative integer or None, got {max_bounces!r}")
    try:
        n = int(max_bounces)
        valid = n == max_bounces and n >= 0 and not isinstance(max_bounces, bool)
    except (TypeError, ValueError, OverflowError):
        valid = False
    if not valid:
        raise ValueError(f"max_bounces must be a non-negative integer or None, got {max_bounces!r}")
    return n


def _checked(rows, cols, values, rho, E, tol):
    """The solver's inputs as arrays, or a ValueError naming what is wrong."""
    rho = np.asarray(rho, dtype=float)
    E = np.asarray(E, dtype=float)
    if E.ndim != 2 or rho.shape != E.shape:
        raise ValueError(f"rho and E must have one shape (N, C), got {rho.shape} and {E.shape}")
    rows = np.asarray(rows)
    cols = np.asarray(cols)
    values = np.asarray(values, dtype=float)
    if not (rows.shape == cols.shape == values.shape and rows.ndim == 1):
        raise ValueError(
            f"rows, cols and values must be 1-D of one length, got {rows.shape}, {cols.shape}, {values.shape}"
        )
    N = len(E)
    if rows.size and (rows.min() < 0 or cols.min() < 0 or rows.max() >= N or cols.max() >= N):
        raise ValueError(
            f"matrix indices must lie in [0, {N}), got rows {rows.min()}..{rows.max()}, "
            f"cols {cols.min()}..{cols.max()}"
        )
    if not np.all(np.isfinite(values)) or (values.size and values.min() < 0):
        raise ValueError("form factors must be finite and non-negative")
    if not np.all(np.isfinite(E)) or (E.size and E.min() < 0):
        raise ValueError("emission must be finite and non-negative")
    if not np.all(np.isfinite(rho)) or (rho.size and (rho.min() < 0 or rho.max() > 1)):
        raise ValueError("reflectance must lie in [0, 1]")
    tol = float(tol)
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a positive number, got {tol!r}")
    return rows.astype(np.intp), cols.astype(np.intp), values, rho, E, tol


class _System:
    """B = E + rho F B with its products, contraction and per-element error bound.

    Attributes
    ----------
    s : ndarray, shape (N, C)
        rho_i sum_j F_ij, the fraction of a uniform radiosity that element i reflects.
    q : ndarray, shape (C,)
        The contraction max_i s_i per channel.
    q2 : ndarray, shape (C,)
        max_i (rho F s)_i = ||(rho F)^2||_inf per channel.
    kappa : ndarray, shape (C,)
        Bound on ||(I - rho F)^-1||_inf, (1 + q) / (1 - q2); inf where q2 >= 1 (no bound).
    """

    def __init__(self, rows, cols, values, rho, E, tol, dense):
        N = len(E)
        self.rows, self.cols, self.values = rows, cols, values
        self.rho, self.E, self.tol = rho, E, tol
        if dense is None and N <= DENSE_MATRIX_LIMIT:
            dense = np.zeros((N, N))
            np.add.at(dense, (rows, cols), values)
        self.dense = dense
        row_sum = np.bincount(rows, weights=values, minlength=N)
        self.s = rho * row_sum[:, None]
        self.q = self.s.max(0)
        self.q2 = self.reflect(self.s).max(0)
        with np.errstate(divide="ignore"):
            self.kappa = np.where(self.q2 < 1.0, (1.0 + self.q) / (1.0 - self.q2), np.inf)

    def dense_matrix(self):
        """F as a dense (N, N) array (built on demand above DENSE_MATRIX_LIMIT)."""
        if self.dense is None:
            N = len(self.E)
            self.dense = np.zeros((N, N))
            np.add.at(self.dense, (self.rows, self.cols), self.values)
        return self.dense

    def reflect(self, B):
        """rho F B, shape (N, C)."""
        if self.dense is not None:
            return self.rho * (self.dense @ B)
        out = np.empty_like(B)
        for c in range(B.shape[1]):
            out[:, c] = np.bincount(self.rows, weights=self.values * B[self.cols, c], minlength=len(B))
        return self.rho * out

    def sweep(self, B):
        """One bounce: (B' = E + rho F B, its change B' - B), both shape (N, C)."""
        new = self.E + self.reflect(B)
        return new, new - B

    def goal(self, B):
        """Largest ||r||_inf per channel for which B' = B + r meets tol everywhere, shape (C,).

        From s_i kappa ||r|| <= tol max(B_i, FLOOR max B), never below ROUNDING max B;
        0 where kappa is infinite (no bound: an iterative solve cannot stop).
        """
        top = np.abs(B).max(0)
        allowed = np.maximum(np.abs(B), FLOOR * top)
        with np.errstate(divide="ignore", invalid="ignore"):
            per_element = np.where(self.s > 0, allowed / self.s, np.inf)
        goal = self.tol / self.kappa * per_element.min(0)
        goal = np.where(np.isfinite(goal), goal, top)  # no element reflects: any residual is exact
        goal = np.maximum(goal, ROUNDING * top)
        return np.where(np.isfinite(self.kappa), goal, 0.0)

    def relative_bound(self, B_final, residual):
        """max over elements and channels of s_i kappa ||r|| / max(B'_i, FLOOR max B')."""
        top = np.abs(B_final).max(0)
        allowed = np.maximum(np.abs(B_final), np.maximum(FLOOR * top, 1e-300))
        norm = np.abs(residual).max(0)
        # kappa may be inf (rows of rho F summing above 1): a zero residual, or a zero row, then
        # contributes 0 (the inf * 0 products are discarded by the wheres)
        with np.errstate(invalid="ignore"):
            factor = np.where(norm > 0, norm * self.kappa, 0.0)
            bound = np.where(self.s > 0, self.s * factor / allowed, 0.0)
        return float(bound.max()) if bound.size else 0.0


def _direct(system):
    """Dense LU per channel (LAPACK gesv); a ValueError if a channel's system is singular."""
    F = system.dense_matrix()
    N = len(F)
    B = np.empty_like(system.E)
    for c in range(B.shape[1]):
        A = np.eye(N) - system.rho[:, c, None] * F
        try:
            B[:, c] = np.linalg.solve(A, system.E[:, c])
        except np.linalg.LinAlgError as error:
            raise ValueError(
                f"the radiosity system is singular in channel {c} (contraction {system.q[c]:.6g}): "
                "a closed room with reflectance 1 has no steady state"
            ) from error
    # B* >= 0 for E >= 0 whenever the Neumann series converges: a clearly negative B means the
    # system was (numerically) singular
    if not np.all(np.isfinite(B)) or B.min() < -1e-9 * np.abs(B).max():
        raise ValueError(f"the radiosity system is numerically singular (contraction {system.q.max():.6g})")
    return B


def overfull(owner, row_sums):
    """The owners (e.g. surfaces) whose largest row sum (`row_sums`, one per row, `owner` its
    owner's index, both shape (R,)) is above 1 + OVERFULL_ROW, which no row can be (a patch sees
    at most its whole view): (their indices, those sums), lists."""
    worst = np.zeros(int(owner.max(initial=-1)) + 1)
    np.maximum.at(worst, owner, row_sums)
    over = np.flatnonzero(worst > 1.0 + OVERFULL_ROW)
    return over.tolist(), worst[over].tolist()


def diverging(history, top, limited=False):
    """A clause saying how sweeps whose residuals (max-norm changes) are `history` diverge, or
    "". Sweeps from E >= 0 converge whenever the spectral radius of their iteration matrix is
    below 1, which q >= 1 alone does not rule out; a residual that is not finite, or (unless the
    sweeps are `limited` to a number of bounces, whose result is defined either way) above
    rounding (ROUNDING * top, top the largest radiosity) and no smaller than DIVERGENCE_SWEEPS
    sweeps before, says the radius is not, where the last sweep would be a silent wrong value (a
    NURBS net that its cyclic flags fold onto itself: 1e305 after 436 hierarchical sweeps)."""
    r, n = history[-1], len(history)
    if not (np.isfinite(r) and np.isfinite(top)):
        return f"radiosity not finite after {n} sweeps"
    if limited or n <= DIVERGENCE_SWEEPS or r <= ROUNDING * top or r < history[-1 - DIVERGENCE_SWEEPS]:
        return ""
    before = history[-1 - DIVERGENCE_SWEEPS]
    return f"residual {r:.3g} after {n} sweeps, {before:.3g} {DIVERGENCE_SWEEPS} sweeps before"


def _jacobi(system, max_bounces, cancel):
    """Sweeps from B = E, up to max_bounces (None: SWEEP_BUDGET), stopped by the per-element bound.

    Returns the iterate before the last sweep (the caller's final sweep completes it) and the
    number of sweeps including that final one. Raises `ConvergenceError` when max_bounces is None
    and the budget runs out.
    """
    limit = SWEEP_BUDGET if max_bounces is None else int(max_bounces)
    if limit == 0:
        return np.zeros_like(system.E), 0
    previous = np.zeros_like(system.E)
    B = system.E.copy()  # zero bounces
    history = []  # each sweep's largest change
    for sweep in range(1, limit + 1):
        if cancel is not None:
            cancel()
        with np.errstate(over="ignore", invalid="ignore"):  # (diverging sweeps: named below)
            new, change = system.sweep(B)
            largest = np.abs(change).max(0)  # per channel
            history.append(float(largest.max(initial=0.0)))
            # stop when the bound for `new` meets tol; B -> new is the final sweep
            if np.all(largest <= system.goal(new)):
                return B, sweep
        how = diverging(history, float(np.abs(new).max(initial=0.0)), limited=max_bounces is not None)
        if how:
            raise ValueError(f"Jacobi sweeps diverge ({how}; contraction {system.q.max():.6g})")
        previous, B = B, new
    if max_bounces is not None:
        return previous, limit
    residual = float(np.abs(change).max() / max(float(np.abs(B).max()), 1e-300))
    raise ConvergenceError(
        f"Jacobi sweeps did not converge in {limit} sweeps (contraction {system.q.max():.6g}, "
        f"relative residual {residual:.3g})",
        residual,
        float((system.goal(B) / np.maximum(np.abs(B).max(0), 1e-300)).min()),
        limit,
    )


def _gmres(system, cancel):
    """Restarted GMRES on (I - rho F) B = E, all channels at once, stopped by the per-element bound.

    GMRES (Saad & Schultz, SIAM J. Sci. Stat. Comput. 7, 1986): each cycle builds an orthonormal
    Krylov basis by modified Gram-Schmidt and minimises the residual's 2-norm (>= its max-norm)
    through Givens rotations of the Hessenberg matrix; a cycle ends at RESTART vectors or when the
    2-norm estimate meets the goal, and the true residual decides. Channels are independent
    systems that share the loop (arrays carry a trailing channel axis).

    Returns
    -------
    B : ndarray, shape (N, C)
    iterations : int
        Products with F.

    Raises
    ------
    ConvergenceError
        When KRYLOV_BUDGET products pass without meeting the goal, or q >= 1 (no bound).
    """
    E = system.E
    N, C = E.shape
    if not np.all(np.isfinite(system.kappa)):
        raise ConvergenceError(
            f"GMRES has no stopping bound: ||(rho F)^2|| = {system.q2.max():.6g} >= 1", np.inf, 0.0, 0
        )
    B = E.copy()
    used = 0
    while True:
        # true residual of the current iterate; stop when it meets the per-element goal
        new, r = system.sweep(B)
        used += 1
        goal = system.goal(new)
        reached = np.abs(r).max(0)
        if np.all(reached <= goal):
            return B, used
        if used >= KRYLOV_BUDGET:
            scale = max(float(np.abs(B).max()), 1e-300)
            raise ConvergenceError(
                f"GMRES did not converge in {used} products with F (contraction {system.q.max():.6g}): "
                f"relative residual {reached.max() / scale:.3g}, needed {goal.min() / scale:.3g}",
                float(reached.max() / scale),
                float(goal.min() / scale),
                used,
            )
        if cancel is not None:
            cancel()

        # one cycle: Arnoldi by modified Gram-Schmidt, Givens rotations on the Hessenberg columns
        m = min(RESTART, KRYLOV_BUDGET - used)
        beta = np.linalg.norm(r, axis=0)
        V = np.zeros((m + 1, N, C))
        V[0] = np.divide(r, beta, out=np.zeros_like(r), where=beta > 0)
        H = np.zeros((m + 1, m, C))
        g = np.zeros((m + 1, C))
        g[0] = beta
        cos, sin = np.ones((m, C)), np.zeros((m, C))
        for j in range(m):
            w = V[j] - system.reflect(V[j])
            used += 1
            for i in range(j + 1):
                H[i, j] = np.einsum("nc,nc->c", w, V[i])
                w -= H[i, j] * V[i]
            H[j + 1, j] = np.linalg.norm(w, axis=0)
            V[j + 1] = np.divide(w, H[j + 1, j], out=np.zeros_like(w), where=H[j + 1, j] > 0)
            # apply the earlier rotations to column j, then the one that zeroes H[j + 1, j]
            for i in range(j):
                top = cos[i] * H[i, j] + sin[i] * H[i + 1, j]
                H[i + 1, j] = -sin[i] * H[i, j] + cos[i] * H[i + 1, j]
                H[i, j] = top
            d = np.hypot(H[j, j], H[j + 1, j])
            live = d > 0  # d == 0: this channel's basis ended (exact), keep its step at zero
            cos[j] = np.where(live, H[j, j] / np.where(live, d, 1.0), 1.0)
            sin[j] = np.where(live, H[j + 1, j] / np.where(live, d, 1.0), 0.0)
            H[j, j] = np.where(live, d, 1.0)
            H[j + 1, j] = 0.0
            g[j + 1] = -sin[j] * g[j]
            g[j] = cos[j] * g[j]
            if cancel is not None:
                cancel()
            # the goal follows the current iterate (the first one is far darker than B*)
            step = _least_squares_step(H, g, V, j + 1)
            if np.all(np.abs(g[j + 1]) <= system.goal(B + step)):
                break
        B = B + step


def _least_squares_step(H, g, V, k):
    """GMRES correction V_k y with R_k y = g_k (R_k the rotated Hessenberg's upper k x k block).

    H : (m + 1, m, C), g : (m + 1, C), V : (m + 1, N, C); returns shape (N, C).
    """
    R = np.moveaxis(H[:k, :k], 2, 0)  # (C, k, k), upper triangular
    y = np.linalg.solve(R, np.moveaxis(g[:k], 1, 0)[:, :, None])[:, :, 0]  # (C, k)
    return np.einsum("knc,ck->nc", V[:k], y)


def _converged_within(system, bounces, cancel):
    """B for a bounce count beyond SWEEP_BUDGET: the converged B if `bounces` provably reach it.

    B* - B_n = (rho F)^(n+1) B* <= s q2^(n // 2) q^(n % 2) max B* per element (F >= 0), so B_n
    equals B* to tol when that is at most tol max(B*_i, FLOOR max B*) / 2 for all i.
    """
    N = len(system.E)
    if N <= DIRECT_SOLVE_LIMIT:
        B, iterations, method = _direct(system), 0, "direct"
    else:
        try:
            B, iterations = _gmres(system, cancel)
            method = "gmres"
        except ConvergenceError:
            if system.dense is None:
                raise
            B, iterations, method = _direct(system), 0, "direct"
    top = np.abs(B).max(0)
    allowed = np.maximum(np.abs(B), FLOOR * top)
    with np.errstate(under="ignore", over="ignore", invalid="ignore"):
        tail = system.s * np.power(system.q2, float(bounces // 2)) * system.q ** (bounces % 2) * top
    if np.all(tail <= system.tol * allowed / 2):
        return B, iterations, method
    raise ValueError(
        f"max_bounces={bounces} needs more than {SWEEP_BUDGET} sweeps and does not reach the "
        f"converged radiosity to tol (contraction {system.q.max():.6g}); use max_bounces=None or at "
        f"most {SWEEP_BUDGET}"
    )
