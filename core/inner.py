"""Point-to-patch form factors F(dA1 -> patch) for many points at once: the inner integral.

- Flat quads near the point: exact contour integral, clipped at the point's horizon
  (`polygon.point_to_polygon`); sphere and disk patches (under similarity maps) likewise
  (`contour.sphere_patch`, `contour.disk_patch`).
- Everything else: adaptive cubature over the patch's dyadic cells (`adaptive.integrate_cells`).
  Cells that bounds prove hidden cost nothing; cells crossed by the point's horizon
  (n1 . e = 0) or by the patch's silhouette (n2 . e = 0) are integrated line by line between
  the roots of those functions, found by the Illinois method, so the kink of the clipped kernel
  never lies inside a Gauss rule. Cells close to the point, with too wide a normal cone, or
  whose lines cross a horizon more than once are refined before they are trusted.
"""

import numpy as np

from .adaptive import integrate_cells
from .bounds import FULL, HIDDEN, cone_code, direction_cone, facing_code
from .contour import cylinder_patch, disk_patch, sphere_patch
from .integrate import cell_nodes
from .kernel import kernel
from .polygon import point_to_polygon
from .primitives import CylinderGeometry, DiskGeometry, QuadGeometry, SphereGeometry
from .quadrature import gauss_legendre

NEAR = 1.0  # a cell is near when its radius exceeds NEAR times its gap to the point
WIDE = np.radians(75.0)  # cells with wider normal cones are refined before use
FAR_EXACT = 1e-3  # below this size/distance ratio a patch is integrated, not contoured
GENERIC, POLYGON, SPHERE, DISK, CYLINDER = 0, 1, 2, 3, 4
ROOT_ITERATIONS = 10


class PointToPatch:
    """Evaluator of F(dA1 -> patch) for points on any patches of a `SurfaceSet`.

    Parameters
    ----------
    surfaces : SurfaceSet
    pyramid : bounds.Pyramid
        Bounds of every patch that may be a target.
    order : int
        Gauss points per direction in a cell.
    samples : int
        Samples per line used to bracket horizon crossings.
    """

    def __init__(self, surfaces, pyramid, order=6, samples=7):
        self.surfaces = surfaces
        self.pyramid = pyramid
        self.order = order
        self.samples = samples
        n = len(surfaces)
        # exact evaluators: flat quads (polygon), spheres and disks under similarity maps (contour)
        self.kind = np.full(n, GENERIC)
        self.corners = np.zeros((n, 4, 3))
        self.front = np.zeros((n, 3))
        self.local_from_world = np.zeros((n, 3, 3))
        self.origin = np.zeros((n, 3))
        self.cylinder = np.zeros((n, 5, 3))
        self.inward = np.array([s._sign < 0 for s in surfaces.surfaces], dtype=bool)
        for k, s in enumerate(surfaces.surfaces):
            geometry = s.geometry
            if isinstance(geometry, QuadGeometry) and geometry.plane is not None:
                self.kind[k] = POLYGON
                corners = geometry.box_corners(s.domain)
                _, normal = s.evaluate(np.mean(s.domain[0]), np.mean(s.domain[1]))
                self.front[k] = normal / np.linalg.norm(normal)
                # contour runs counter-clockwise about the front (mirrors and flips reverse it)
                winding = np.cross(corners[2] - corners[0], corners[3] - corners[1])
                self.corners[k] = corners if winding @ normal > 0 else corners[::-1]
            elif (
                isinstance(geometry, (SphereGeometry, DiskGeometry)) and geometry.similarity_scale is not None
            ):
                self.kind[k] = SPHERE if isinstance(geometry, SphereGeometry) else DISK
                self.local_from_world[k] = np.linalg.inv(geometry.linear)
                self.origin[k] = geometry.offset
            elif isinstance(geometry, CylinderGeometry) and geometry.exact_area(s.domain) is not None:
                self.kind[k] = CYLINDER
                radius = np.linalg.norm(geometry.linear[:, 0])
                self.cylinder[k, 0] = geometry.offset
                self.cylinder[k, 1:4] = geometry.linear.T / [[radius], [radius], [1.0]]
                self.cylinder[k, 4, 0] = radius
        zero = np.zeros_like(pyramid.patches)
        slot, cell = pyramid.index(pyramid.patches, zero, zero, zero)
        self.root_center = np.zeros((n, 3))
        self.root_radius = np.zeros(n)
        self.root_center[pyramid.patches] = pyramid.center[slot, cell]
        self.root_radius[pyramid.patches] = pyramid.radius[slot, cell]
        self.min_radius = 1e-3 * self.root_radius

    def __call__(self, x1, n1, patch, tolerance):
        """F(dA1 -> patch) at many points.

        Parameters
        ----------
        x1 : ndarray, shape (K, 3)
            Points (m).
        n1 : ndarray, shape (K, 3)
            Unit front normals at the points.
        patch : ndarray of int, shape (K,)
            Target patch of each point.
        tolerance : ndarray, shape (K,)
            Absolute error allowed for each value.

        Returns
        -------
        F, error : ndarray, shape (K,)
        evaluations : int
            Kernel evaluations, counting each contour edge term as one.
        """
        F = np.zeros(len(x1))
        error = np.zeros(len(x1))
        distance = np.linalg.norm(x1 - self.root_center[patch], axis=-1)
        # far away, a Gauss rule is exact enough and contours would lose digits to cancellation
        near = self.root_radius[patch] > FAR_EXACT * distance
        kind = np.where(near, self.kind[patch], GENERIC)
        evaluations = 0
        sel = np.flatnonzero(kind == POLYGON)
        if sel.size:
            p = patch[sel]
            F[sel], count = point_to_polygon(x1[sel], n1[sel], self.corners[p], self.front[p])
            evaluations += count
        for code, region in ((SPHERE, sphere_patch), (DISK, disk_patch)):
            sel = np.flatnonzero(kind == code)
            if sel.size:
                F[sel], count = self._contour(region, x1[sel], n1[sel], patch[sel])
                evaluations += count
        sel = np.flatnonzero(kind == CYLINDER)
        if sel.size:
            p = patch[sel]
            F[sel] = cylinder_patch(
                x1[sel],
                n1[sel],
                self.cylinder[p],
                self.surfaces.boxes[p],
                self.surfaces.orientation[p],
                self.inward[p],
            )
            evaluations += 40 * sel.size
        rest = np.flatnonzero(kind == GENERIC)
        if rest.size:
            X, N, P = x1[rest], n1[rest], patch[rest]

            def evaluate(cells):
                return self._evaluate_cells(cells, X, N, P)

            F[rest], error[rest], count = integrate_cells(evaluate, rest.size, tolerance[rest])
            evaluations += count
        return F, error, evaluations

    def _contour(self, region, x1, n1, patch):
        """Exact F for sphere or disk patches: map to local coordinates and integrate the contour.

        Patches wider than pi in azimuth are done in two halves (each a convex lune or sector).
        """
        M = self.local_from_world[patch]
        local_x = np.einsum("kij,kj->ki", M, x1 - self.origin[patch])
        local_n = np.einsum("kij,kj->ki", M, n1)
        local_n /= np.linalg.norm(local_n, axis=-1, keepdims=True)
        box = self.surfaces.boxes[patch]
        wide = (box[:, 3] - box[:, 2] > np.pi) & (box[:, 3] - box[:, 2] < 2 * np.pi * (1 - 1e-12))
        middle = 0.5 * (box[:, 2] + box[:, 3])
        first = box.copy()
        first[wide, 3] = middle[wide]
        F = region(local_x, local_n, first, self.inward[patch])
        sel = np.flatnonzero(wide)
        if sel.size:
            second = box[sel].copy()
            second[:, 2] = middle[sel]
            F[sel] += region(local_x[sel], local_n[sel], second, self.inward[patch[sel]])
        return F, 6 * 13 * (len(patch) + sel.size)

    # ------------------------------------------------------------------ cells
    def _evaluate_cells(self, cells, x1, n1, patch):
        """Rule values of dyadic target cells; see `adaptive.integrate_cells` for the contract."""
        X, N, p = x1[cells.item], n1[cells.item], patch[cells.item]
        box = self.surfaces.cell_boxes(p, cells.level, cells.i, cells.j)
        center, radius, axis, half, flat = self.pyramid.bounds(p, cells.level, cells.i, cells.j)

        # which cells are hidden, fully visible, or crossed by a horizon or silhouette
        code1 = facing_code(np.einsum("ki,ki->k", N, center - X), radius)
        direction, spread, distance = direction_cone(center, X, radius)
        code2 = cone_code(axis, half, direction, spread)
        plane_height = np.einsum("ki,ki->k", axis, X - center)
        scale = radius + distance
        code2 = np.where(flat, np.where(plane_height > 1e-12 * scale, FULL, HIDDEN), code2)
        hidden = (code1 == HIDDEN) | (code2 == HIDDEN)
        full = (code1 == FULL) & (code2 == FULL)

        near = radius > NEAR * np.maximum(distance - radius, 0.0)
        forced = ~hidden & ((near & (radius > self.min_radius[p])) | (~flat & (half > WIDE)))
        value = np.zeros(len(p))
        evaluations = 0

        sel = np.flatnonzero(~hidden & full)
        if sel.size:
            value[sel], count = self._plain(X[sel], N[sel], p[sel], box[sel])
            evaluations += count
        sel = np.flatnonzero(~hidden & ~full)
        if sel.size:
            value[sel], unreliable, count = self._clipped(
                X[sel], N[sel], p[sel], box[sel], code1[sel] != FULL, code2[sel] != FULL
            )
            forced[sel] |= unreliable
            evaluations += count
        return value, np.zeros(len(p)), forced, evaluations

    def _plain(self, X, N, p, box):
        """Tensor Gauss rule over each cell, shape (K,)."""
        u, v, w = cell_nodes(box, self.order)
        P, N2 = self.surfaces.evaluate(np.repeat(p, u.shape[1]), u.ravel(), v.ravel())
        k = kernel(X[:, None], N[:, None], P.reshape(u.shape + (3,)), N2.reshape(u.shape + (3,)))
        return (k * w).sum(1), u.size

    def _clipped(self, X, N, p, box, active1, active2):
        """Line-by-line Gauss rule between the roots of the horizon and silhouette functions.

        Parameters
        ----------
        X, N : ndarray, shape (K, 3)
            Points and unit normals.
        p : ndarray of int, shape (K,)
        box : ndarray, shape (K, 4)
        active1, active2 : ndarray of bool, shape (K,)
            Whether the horizon (n1 . e) / silhouette (n2 . e) may cross the cell.

        Returns
        -------
        value : ndarray, shape (K,)
        unreliable : ndarray of bool, shape (K,)
            Some line crosses a horizon more than once: refine the cell.
        evaluations : int
        """
        K = len(p)
        n, m = self.order, self.samples
        rule = gauss_legendre(n)
        cells = _CellLines(self.surfaces, X, N, p, box)

        # integrate along the direction in which the active functions change most
        rows = np.repeat(np.arange(K), 3)
        g1p, g2p, _, _ = cells.values(rows, np.tile([0.5, 0.75, 0.5], K), np.tile([0.5, 0.5, 0.75], K))
        weight_u, weight_v = np.zeros(K), np.zeros(K)
        for g, active in ((g1p.reshape(K, 3), active1), (g2p.reshape(K, 3), active2)):
            cu, cv = np.abs(g[:, 1] - g[:, 0]), np.abs(g[:, 2] - g[:, 0])
            total = cu + cv
            ok = active & (total > 0)
            weight_u += np.divide(cu, total, out=np.zeros(K), where=ok)
            weight_v += np.divide(cv, total, out=np.zeros(K), where=ok)
        cells.along_v = weight_v >= weight_u

        # bracket the crossings on n lines (Gauss abscissas across) with m samples along each
        t_samples = np.linspace(0.0, 1.0, m)
        shape = (K, n, m)
        rows = np.broadcast_to(np.arange(K)[:, None, None], shape).ravel()
        s_grid = np.broadcast_to(rule.points[None, :, None], shape).ravel()
        t_grid = np.broadcast_to(t_samples[None, None, :], shape).ravel()
        g1s, g2s, _, _ = cells.values(rows, s_grid, t_grid)
        lo, hi = np.zeros((K, n)), np.ones((K, n))
        unreliable = np.zeros(K, dtype=bool)
        for which, g, active in ((0, g1s.reshape(shape), active1), (1, g2s.reshape(shape), active2)):
            positive = g >= 0.0
            change = positive[..., 1:] != positive[..., :-1]
            changes = change.sum(-1)
            unreliable |= active & (changes > 1).any(-1)
            empty = active[:, None] & (changes == 0) & ~positive[..., 0]
            lo, hi = np.where(empty, 1.0, lo), np.where(empty, 0.0, hi)
            single = active[:, None] & (changes == 1)
            if not single.any():
                continue
            r, line = np.nonzero(single)
            k = np.argmax(change[r, line], -1)
            root = cells.root(
                which, r, rule.points[line], t_samples[k], t_samples[k + 1], g[r, line, k], g[r, line, k + 1]
            )
            rises = ~positive[r, line, 0]
            lo[r, line] = np.where(rises, np.maximum(lo[r, line], root), lo[r, line])
            hi[r, line] = np.where(rises, hi[r, line], np.minimum(hi[r, line], root))
        length = np.maximum(hi - lo, 0.0)

        # Gauss rule along each line between its roots
        shape = (K, n, n)
        rows = np.broadcast_to(np.arange(K)[:, None, None], shape).ravel()
        s_grid = np.broadcast_to(rule.points[None, :, None], shape).ravel()
        t_nodes = (lo[..., None] + length[..., None] * rule.points[None, None, :]).ravel()
        _, _, P, N2 = cells.values(rows, s_grid, t_nodes)
        k = kernel(X[rows], N[rows], P, N2).reshape(shape)
        line_integrals = (k * rule.weights).sum(-1) * length
        value = (line_integrals * rule.weights).sum(-1) * (box[:, 1] - box[:, 0]) * (box[:, 3] - box[:, 2])
        return value, unreliable, cells.evaluations


class _CellLines:
    """Cells addressed by line coordinates: s across the lines, t along them, both in [0, 1].

    Lines run along v where `along_v` is set, along u elsewhere.
    """

    def __init__(self, surfaces, X, N, p, box):
        self.surfaces, self.X, self.N, self.p, self.box = surfaces, X, N, p, box
        self.along_v = np.ones(len(p), dtype=bool)
        self.evaluations = 0

    def values(self, rows, s, t):
        """Horizon g1 = n1 . (x2 - x1), silhouette g2 = n2 . (x1 - x2), points and normals.

        Parameters
        ----------
        rows : ndarray of int, shape (L,)
            Cell of each sample.
        s, t : ndarray, shape (L,)

        Returns
        -------
        g1, g2 : ndarray, shape (L,)
        P, N2 : ndarray, shape (L, 3)
        """
        along_v = self.along_v[rows]
        a, b = np.where(along_v, s, t), np.where(along_v, t, s)
        box = self.box[rows]
        u = box[:, 0] + a * (box[:, 1] - box[:, 0])
        v = box[:, 2] + b * (box[:, 3] - box[:, 2])
        P, N2 = self.surfaces.evaluate(self.p[rows], u, v)
        self.evaluations += u.size
        e = P - self.X[rows]
        return np.einsum("ki,ki->k", self.N[rows], e), -np.einsum("ki,ki->k", N2, e), P, N2

    def root(self, which, rows, s, a, b, fa, fb):
        """Root in t of g_which on lines (rows, s), bracketed by [a, b] where g changes sign.

        The Illinois variant of regula falsi (Dowell & Jarratt 1971, BIT 11:168-174) converges
        superlinearly and never leaves the bracket.

        Returns
        -------
        ndarray, shape (L,)
        """
        for _ in range(ROOT_ITERATIONS):
            step = np.divide(fb * (b - a), fb - fa, out=np.zeros_like(a), where=fb != fa)
            c = b - step
            fc = self.values(rows, s, c)[which]
            crossed = (fc >= 0.0) != (fb >= 0.0)
            a, fa = np.where(crossed, b, a), np.where(crossed, fb, 0.5 * fa)
            b, fb = c, fc
        return b
