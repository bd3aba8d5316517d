"""Point-to-patch form factors F(dA1 -> patch) for many points at once: the inner integral.

- Flat quads near the point: exact contour integral, clipped at the point's horizon
  (`polygon.point_to_polygon`); sphere and disk patches (under similarity maps) likewise
  (`contour.sphere_patch`, `contour.disk_patch`).
- Whole ellipsoids seen from outside: a contour integral around the part the point sees
  (`ellipsoid.whole_ellipsoid`); points it does not handle go on as below.
- Everything else: adaptive cubature over the patch's dyadic cells (`adaptive.integrate_cells`).
  Cells that bounds prove hidden cost nothing. Cells that bounds prove wholly above the
  point's horizon and facing it are integrated by the contour of their boundary
  (`cellcontour.contour_rule`, Stokes / Sparrow), so a patch the point sees wholly costs one
  contour and the cells only resolve the horizon and silhouette. The others are integrated line
  by line from cached samples, between the roots of the horizon and silhouette functions
  (`cellrule.line_rule`), so the kink of the clipped kernel never lies inside a polynomial rule.
  Cells close to the point, with too wide a normal cone, or whose lines cross a horizon more
  than once are refined before they are trusted.
"""

import numpy as np

from .adaptive import SPLIT_ANY, SPLIT_NONE, SPLIT_U, SPLIT_V, CellBatch, integrate_cells
from .bounds import FULL, HIDDEN, cone_code, direction_cone, facing_code, lengths
from .cellcontour import NODES, EdgeCache, contour_rule
from .cellrule import LINES, MAX_LEVEL, SAMPLES, CellCache, line_rule
from .contour import cylinder_patch, disk_patch, sphere_patch
from .ellipsoid import whole_ellipsoid
from .kinds import CYLINDER, DISK, GENERIC, POLYGON, SPHERE
from .polygon import point_to_polygon
from .primitives import QuadGeometry

NEAR = 1.0  # a cell is near when its radius exceeds NEAR times its gap to the point
WIDE = np.radians(60.0)  # cells whose normals turn more than this are refined before use
POINT_BUDGET = 400_000  # kernel evaluations per point after which refinement stops
START_CELLS = POINT_BUDGET // (20 * LINES * SAMPLES)  # forced splits made before the adaptive run
FAR_EXACT = 1e-7  # below this size/distance ratio a patch is integrated, not contoured (the
# contour terms cancel to ~(size/distance)^2, losing about distance/size ulps)
CONTOUR_GAP = 0.5  # a cell seen wholly is contoured when its gap to the point is >= this many radii
CONTOUR_FAR = 1e-6  # ... and its radius at least this fraction of its distance (cancellation)
MAX_HULL = 1024  # patches with more hull points than this are not tested against horizons whole
FINAL = 1e-3  # a contoured cell whose error is below this fraction of the point's tolerance is final


class PointToPatch:
    """Evaluator of F(dA1 -> patch) for points on any patches of a `SurfaceSet`.

    Parameters
    ----------
    surfaces : SurfaceSet
    pyramid : bounds.Pyramid
        Bounds of every patch that may be a target.
    """

    def __init__(self, surfaces, pyramid):
        self.surfaces = surfaces
        self.pyramid = pyramid
        n = len(surfaces)
        # exact evaluators: flat quads (polygon), spheres and disks under similarity maps (contour)
        self.kind = np.full(n, GENERIC)
        self.corners = np.zeros((n, 4, 3))
        self.front = np.zeros((n, 3))
        self.local_from_world = np.zeros((n, 3, 3))
        self.origin = np.zeros((n, 3))
        self.cylinder = np.zeros((n, 5, 3))
        self.inward = np.array([s.is_flipped for s in surfaces.surfaces], dtype=bool)
        flat = QuadGeometry.flat_patches(surfaces.surfaces)
        if flat:
            patches = [surfaces.surfaces[k] for k in flat]
            corners, _ = QuadGeometry.patch_frames(patches)
            self.kind[flat] = POLYGON
            # the plane's unit normal is that of dP/du x dP/dv (a flat quad's is constant)
            normal = np.array([p.geometry.plane[1] * p.orientation for p in patches])
            self.front[flat] = normal
            # contour runs counter-clockwise about the front (mirrors and flips reverse it)
            winding = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
            reverse = np.einsum("ki,ki->k", winding, normal) <= 0
            self.corners[flat] = np.where(reverse[:, None, None], corners[:, ::-1], corners)
        for k, s in enumerate(surfaces.surfaces):
            geometry = s.geometry
            if self.kind[k] == POLYGON:
                continue
            self.kind[k] = geometry.exact_kind(s.domain)
            if self.kind[k] in (SPHERE, DISK):
                self.local_from_world[k] = np.linalg.inv(geometry.linear)
                self.origin[k] = geometry.offset
            elif self.kind[k] == CYLINDER:
                radius = np.linalg.norm(geometry.linear[:, 0])
                self.cylinder[k, 0] = geometry.offset
                self.cylinder[k, 1:4] = geometry.linear.T / [[radius], [radius], [1.0]]
                self.cylinder[k, 4, 0] = radius
        self.whole_sphere = np.zeros(n, dtype=bool)
        self.sphere_center = np.zeros((n, 3))
        self.sphere_radius = np.zeros(n)
        # whole ellipsoids (not spheres) seen from outside: the contour of their visible part
        # (the inside of one, seen from outside through its near wall, covers the same directions
        # above the point's horizon: the same factor)
        self.whole_ellipsoid = np.zeros(n, dtype=bool)
        self.linear = np.zeros((n, 3, 3))
        for k, s in enumerate(surfaces.surfaces):
            whole = s.geometry.whole_ellipsoid(s.domain)
            if self.kind[k] == SPHERE and whole and not self.inward[k]:
                self.whole_sphere[k] = True
                self.sphere_center[k] = s.geometry.offset
                self.sphere_radius[k] = s.geometry.similarity_scale
            elif self.kind[k] == GENERIC and whole:
                # (a NURBS net may be an ellipsoid with dP/du x dP/dv pointing in)
                self.inward[k] = s.is_flipped == s.geometry.convex_outward
                self.whole_ellipsoid[k] = True
                self.linear[k] = s.geometry.linear
                self.local_from_world[k] = np.linalg.inv(s.geometry.linear)
                self.origin[k] = s.geometry.offset
        zero = np.zeros_like(pyramid.patches)
        slot, cell = pyramid.index(pyramid.patches, zero, zero, zero)
        self.root_center = np.zeros((n, 3))
        self.root_radius = np.zeros(n)
        self.root_center[pyramid.patches] = pyramid.center[slot, cell]
        self.root_radius[pyramid.patches] = pyramid.radius[slot, cell]
        self.min_radius = 1e-3 * self.root_radius
        # hulls of generic patches (NURBS: the control net; bilinear quads: the corners), padded
        # by repeating a point: a point's horizon that no hull point is below leaves the whole
        # patch above it (the line rule's horizon then never cuts a cell)
        hulls = [
            s.geometry.hull_points(s.domain) if self.kind[k] == GENERIC else None
            for k, s in enumerate(surfaces.surfaces)
        ]
        hulls = [h if h is not None and len(h) <= MAX_HULL else None for h in hulls]
        width = max([1] + [len(h) for h in hulls if h is not None])
        self.hull = np.full((n, width, 3), np.nan)
        self.has_hull = np.array([h is not None for h in hulls], dtype=bool)
        for k, h in enumerate(hulls):
            if h is not None:
                self.hull[k] = np.concatenate([h, np.repeat(h[:1], width - len(h), 0)])
        self.cache = CellCache(surfaces, pyramid)
        self.edges = EdgeCache(surfaces)
        # lines where a patch may not be analytic (NURBS knots): no contour across them; padded
        # with NaN (shape (n, 2, B))
        breaks = [s.geometry.breaks for s in surfaces.surfaces]
        width = max([1] + [max(len(b[0]), len(b[1])) for b in breaks])
        self.breaks = np.full((n, 2, width), np.nan)
        for k, (bu, bv) in enumerate(breaks):
            self.breaks[k, 0, : len(bu)] = bu
            self.breaks[k, 1, : len(bv)] = bv

    def __call__(self, x1, n1, patch, tolerance, budget=None):
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
        budget : int, optional
            Kernel evaluations the adaptive cells of all points together may spend, if less than
            POINT_BUDGET per point (a caller's own budget running out). Values then carry the
            errors they reached.

        Returns
        -------
        F, error : ndarray, shape (K,)
        evaluations : int
            Kernel evaluations: point pairs, plus for exact inner integrals one per point and one per
            boundary piece (edge, arc, horizon sweep) integrated in closed form.
        """
        F = np.zeros(len(x1))
        error = np.zeros(len(x1))
        distance = lengths(x1 - self.root_center[patch])
        # far away, a Gauss rule is exact enough and contours would lose digits to cancellation
        near = self.root_radius[patch] > FAR_EXACT * distance
        kind = np.where(near, self.kind[patch], GENERIC)
        evaluations = 0
        sel = np.flatnonzero(kind == POLYGON)
        if sel.size:
            p = patch[sel]
            F[sel], count = point_to_polygon(x1[sel], n1[sel], self.corners[p], self.front[p])
            evaluations += count
        # a whole sphere wholly above the point's horizon: F = r^2 cos(theta) / d^2 (Nusselt's
        # analogy: its projected solid angle is that of a disk of radius r facing the point)
        sel = np.flatnonzero(self.whole_sphere[patch])  # (also far: no cancellation here)
        if sel.size:
            p = patch[sel]
            toward = self.sphere_center[p] - x1[sel]
            d2 = np.einsum("ki,ki->k", toward, toward)
            height = np.einsum("ki,ki->k", toward, n1[sel])
            r = self.sphere_radius[p]
            above = height >= r * (1.0 + 1e-12)
            F[sel[above]] = r[above] ** 2 * height[above] / (d2[above] * np.sqrt(d2[above]))
            kind[sel[above]] = -1  # done
            evaluations += int(above.sum())
        sel = np.flatnonzero((kind == GENERIC) & self.whole_ellipsoid[patch])
        if sel.size:
            p = patch[sel]
            f, e, ok, count = whole_ellipsoid(
                x1[sel],
                n1[sel],
                self.origin[p],
                self.linear[p],
                self.local_from_world[p],
                self.inward[p],
                tolerance[sel],
            )
            F[sel[ok]], error[sel[ok]] = f[ok], e[ok]
            kind[sel[ok]] = -1  # done
            evaluations += count
        for code, region in ((SPHERE, sphere_patch), (DISK, disk_patch)):
            sel = np.flatnonzero(kind == code)
            if sel.size:
                F[sel], count = self._contour(region, x1[sel], n1[sel], patch[sel])
                evaluations += count
        sel = np.flatnonzero(kind == CYLINDER)
        if sel.size:
            p = patch[sel]
            F[sel], count = cylinder_patch(
                x1[sel],
                n1[sel],
                self.cylinder[p],
                self.surfaces.boxes[p],
                self.surfaces.orientation[p],
                self.inward[p],
            )
            evaluations += count + sel.size
        rest = np.flatnonzero(kind == GENERIC)
        above = np.zeros(len(x1), dtype=bool)
        if rest.size:
            # the patch's hull wholly on or above the point's horizon, or wholly on or below it
            # (then F = 0 exactly)
            low, high = self._hull_heights(x1[rest], n1[rest], patch[rest])
            above[rest] = low >= 0.0
            rest = rest[high > 0.0]
        if rest.size:
            # a patch the point sees wholly, front on: one contour of its boundary, if converged
            roots = CellBatch.roots(np.arange(rest.size))
            value, extra, _, count, contoured = self._rule_cells(
                roots, x1[rest], n1[rest], patch[rest], above[rest], contour_only=True
            )
            evaluations += count
            ok = contoured & (extra <= tolerance[rest])
            F[rest[ok]], error[rest[ok]] = value[ok], extra[ok]
            rest = rest[~ok]
        if rest.size:
            X, N, P, T, A = x1[rest], n1[rest], patch[rest], tolerance[rest], above[rest]

            def evaluate(cells):
                return self._evaluate_cells(cells, X, N, P, T, A)

            F[rest], error[rest], count = integrate_cells(
                evaluate,
                rest.size,
                tolerance[rest],
                max_level=MAX_LEVEL,
                max_evaluations=min(POINT_BUDGET * rest.size, budget if budget is not None else np.inf),
                start=self._start_cells(X, N, P, A),
            )
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
        F, count = region(local_x, local_n, first, self.inward[patch])
        sel = np.flatnonzero(wide)
        if sel.size:
            second = box[sel].copy()
            second[:, 2] = middle[sel]
            F2, count2 = region(local_x[sel], local_n[sel], second, self.inward[patch[sel]])
            F[sel] += F2
            count += count2
        return F, count + len(patch)

    # ------------------------------------------------------------------ cells
    def _hull_heights(self, x1, n1, patch):
        """Least and greatest n1 . (h - x1) over each patch's hull points h, shapes (K,) (-inf and
        +inf for patches without a hull: only generic patches have one).

        Parameters
        ----------
        x1, n1 : ndarray, shape (K, 3)
            Points and unit normals of planes.
        patch : ndarray of int, shape (K,)
        """
        heights = np.einsum("khi,ki->kh", self.hull[patch], n1) - np.einsum("ki,ki->k", x1, n1)[:, None]
        has = self.has_hull[patch]
        return np.where(has, heights.min(1), -np.inf), np.where(has, heights.max(1), np.inf)

    def hull_above(self, center, radius, axis, half, flat, patch):
        """Whether each patch's hull lies on or above every tangent plane of a source cell (then
        no point of the cell has a horizon that cuts the patch).

        For x within `radius` of `center` and a normal n within `half` of `axis`,
        n . (h - x) >= axis . (h - center) - radius - 2 sin(half / 2) (|h - center| + radius);
        a flat cell's points all lie in the plane through `center` normal to `axis`.

        Parameters
        ----------
        center, axis : ndarray, shape (K, 3)
        radius, half : ndarray, shape (K,)
        flat : ndarray of bool, shape (K,)
        patch : ndarray of int, shape (K,)

        Returns
        -------
        ndarray of bool, shape (K,) (False for patches without a hull)
        """
        offset = self.hull[patch] - center[:, None]
        height = np.einsum("khi,ki->kh", offset, axis)
        reach = lengths(offset) + radius[:, None]
        margin = np.where(
            flat[:, None],
            height + 1e-12 * reach,
            height - radius[:, None] - 2.0 * np.sin(0.5 * half)[:, None] * reach,
        )
        return self.has_hull[patch] & (margin.min(1) >= 0.0)

    def _evaluate_cells(self, cells, x1, n1, patch, tolerance, above):
        """Rule values of dyadic target cells; see `adaptive.integrate_cells` for the contract.

        Contoured cells whose error estimate is below FINAL times their point's tolerance
        (shape (I,)) are final: the adaptive method takes them as they are.
        """
        value, extra, forced, evaluations, contoured = self._rule_cells(cells, x1, n1, patch, above)
        final = contoured & (extra <= FINAL * tolerance[cells.item])
        return value, extra, forced, evaluations, final

    def _classify(self, cells, x1, n1, patch, above):
        """What bounds alone tell of target cells, before any rule runs.

        Parameters are those of `_rule_cells`.

        Returns
        -------
        rows : ndarray of int, shape (K,)
            The cells' rows in the sample cache.
        hidden : ndarray of bool, shape (K,)
            Proved wholly below the point's horizon or facing away from it.
        forced : ndarray of int8, shape (K,)
            SPLIT_U / SPLIT_V for cells too near the point (radius above NEAR times the gap) or
            too wide (normals turning by more than WIDE) for the line rule, SPLIT_NONE otherwise.
        contoured : ndarray of bool, shape (K,)
            Proved wholly above the horizon, facing the point, not too close to it and with
            analytic edges: integrated by their boundary contour, whatever `forced` says.
        active1, active2 : ndarray of bool, shape (K,)
            Whether the point's horizon, the cell's silhouette may cross the cell.
        """
        X, p = x1[cells.item], patch[cells.item]
        rows = self.cache.lookup(p, cells.lu, cells.lv, cells.i, cells.j)
        cache = self.cache
        center, radius, axis, half = (
            cache.center[rows],
            cache.radius[rows],
            cache.axis[rows],
            cache.half[rows],
        )
        flat = self.pyramid.flat[self.pyramid.slot_of[p]]

        # which cells are hidden, fully visible, or crossed by a horizon or silhouette
        code1 = facing_code(np.einsum("ki,ki->k", n1[cells.item], center - X), radius)
        # (on the horizon the clipped kernel is the smooth one too: zero)
        code1 = np.where(above[cells.item] & (code1 != HIDDEN), FULL, code1)
        direction, spread, distance = direction_cone(center, X, radius)
        code2 = cone_code(axis, half, direction, spread)
        plane_height = np.einsum("ki,ki->k", axis, X - self.pyramid.plane_point[self.pyramid.slot_of[p]])
        scale = radius + distance
        code2 = np.where(flat, np.where(plane_height > 1e-12 * scale, FULL, HIDDEN), code2)
        hidden = (code1 == HIDDEN) | (code2 == HIDDEN)

        near = ~hidden & (radius > NEAR * np.maximum(distance - radius, 0.0)) & (radius > self.min_radius[p])
        # split a near cell across its longer side, a wide one (normals turning by more than
        # WIDE along its middle lines) across its larger turn
        span, turn = cache.span[rows], cache.turn[rows]
        wide = ~hidden & ~flat & (turn.sum(1) > WIDE)
        forced = np.full(len(p), SPLIT_NONE, dtype=np.int8)
        forced[wide] = np.where(turn[wide, 0] >= turn[wide, 1], SPLIT_U, SPLIT_V)
        forced[near] = np.where(span[near, 0] >= span[near, 1], SPLIT_U, SPLIT_V)
        # proved wholly above the horizon and facing the point, and not too close to it: the
        # contour of the cell's boundary (neither near nor wide cells need splitting then)
        gap = distance - radius
        contoured = (
            ~hidden
            & (code1 == FULL)
            & (code2 == FULL)
            & (gap >= CONTOUR_GAP * radius)
            & (radius >= CONTOUR_FAR * distance)
        )
        sel = np.flatnonzero(contoured)
        if sel.size:
            # edges must be analytic: a cell straddling a knot line takes the line rule
            box = self.surfaces.cell_boxes(p[sel], cells.lu[sel], cells.lv[sel], cells.i[sel], cells.j[sel])
            b = self.breaks[p[sel]]
            with np.errstate(invalid="ignore"):
                straddle = ((b[:, 0] > box[:, :1]) & (b[:, 0] < box[:, 1:2])).any(1) | (
                    (b[:, 1] > box[:, 2:3]) & (b[:, 1] < box[:, 3:4])
                ).any(1)
            contoured[sel[straddle]] = False
        forced[contoured] = SPLIT_NONE
        return rows, hidden, forced, contoured, code1 != FULL, code2 != FULL

    def _start_cells(self, x1, n1, patch, above):
        """Each item's cells after every split that bounds force (near and wide cells), hidden
        cells dropped: the partition the adaptive integral starts from (no rule runs on a cell
        it would split anyway, nor on the halves across which it would not).

        Parameters are those of `_rule_cells` (one item per point).

        Returns
        -------
        adaptive.CellBatch
        """
        cells = CellBatch.roots(np.arange(len(x1)))
        count = np.ones(len(x1), dtype=np.int64)  # cells per item so far
        done = []
        for _ in range(2 * MAX_LEVEL):
            _, hidden, forced, _, _, _ = self._classify(cells, x1, n1, patch, above)
            split = ~hidden & (forced != SPLIT_NONE) & (cells.level < MAX_LEVEL)
            # (an item whose start would spend a good part of its budget is left to the adaptive
            # integral, which splits within the budget)
            split &= count[cells.item] < START_CELLS
            count += np.bincount(cells.item[split], minlength=len(x1))
            done.append(cells.take(np.flatnonzero(~hidden & ~split)))
            if not split.any():
                break
            halves = cells.take(np.flatnonzero(split)).halves()
            along_u = forced[split] == SPLIT_U
            pick = 4 * np.arange(along_u.size)[:, None] + np.where(along_u[:, None], [0, 1], [2, 3])
            cells = halves.take(pick.ravel())
        else:
            done.append(cells)
        return CellBatch.concatenate(done)

    def _rule_cells(self, cells, x1, n1, patch, above, contour_only=False):
        """Rule values of dyadic target cells: contour, line rule, or zero for hidden cells.

        Parameters
        ----------
        cells : adaptive.CellBatch, K cells
        x1, n1 : ndarray, shape (I, 3)
            Points and unit normals of the items (cells.item indexes them).
        patch : ndarray of int, shape (I,)
        above : ndarray of bool, shape (I,)
            The item's whole patch is proved on or above its point's horizon (by its hull).
        contour_only : bool
            Only the contour rule: cells it cannot take get value 0 and `contoured` False.

        Returns
        -------
        value, extra : ndarray, shape (K,)
            Integrals over the cells and known errors (contoured cells: the contour's error
            estimate, `cellcontour.contour_rule`).
        forced : ndarray of int8, shape (K,)
            Split codes (`adaptive.SPLIT_*`).
        evaluations : int
        contoured : ndarray of bool, shape (K,)
            Cells integrated by their boundary contour (proved wholly visible and facing).
        """
        X, N, p = x1[cells.item], n1[cells.item], patch[cells.item]
        rows, hidden, forced, contoured, active1, active2 = self._classify(cells, x1, n1, patch, above)
        cache = self.cache
        value = np.zeros(len(p))
        extra = np.zeros(len(p))
        evaluations = 0
        sel = np.flatnonzero(contoured)
        if sel.size:
            edges = self.edges.lookup(p[sel], cells.lu[sel], cells.lv[sel], cells.i[sel], cells.j[sel])
            value[sel], extra[sel] = contour_rule(
                X[sel], N[sel], self.edges.points[edges], self.edges.steps[edges]
            )
            evaluations += sel.size * NODES
        if contour_only:
            return value, extra, forced, evaluations, contoured
        sel = np.flatnonzero(~hidden & ~contoured)
        if sel.size:
            r = rows[sel]
            # lines run along the direction in which the active functions change most
            along = self._along(
                X[sel], N[sel], cache.points[r, 0], cache.normals[r, 0], active1[sel], active2[sel]
            )
            d = np.where(along, 0, 1)
            v, unreliable = line_rule(
                X[sel], N[sel], cache.points[r, d], cache.normals[r, d], active1[sel], active2[sel]
            )
            box = self.surfaces.cell_boxes(p[sel], cells.lu[sel], cells.lv[sel], cells.i[sel], cells.j[sel])
            value[sel] = v * (box[:, 1] - box[:, 0]) * (box[:, 3] - box[:, 2])
            forced[sel[unreliable & (forced[sel] == SPLIT_NONE)]] = SPLIT_ANY
            evaluations += sel.size * LINES * SAMPLES
        return value, extra, forced, evaluations, contoured

    @staticmethod
    def _along(X, N, points, normals, active1, active2):
        """True where the active horizon functions vary more along direction-0 lines than across.

        Parameters
        ----------
        X, N : ndarray, shape (K, 3)
        points, normals : ndarray, shape (K, n, m, 3)
            Direction-0 samples (lines along v).
        active1, active2 : ndarray of bool, shape (K,)
        """
        e = points - X[:, None, None, :]
        along = np.zeros(len(X))
        across = np.zeros(len(X))
        for g, active in (
            (np.einsum("klmi,ki->klm", e, N), active1),
            (-np.einsum("klmi,klmi->klm", normals, e), active2),
        ):
            a = np.abs(g[:, :, -1] - g[:, :, 0]).mean(1)
            c = np.abs(g[:, -1, :] - g[:, 0, :]).mean(1)
            total = a + c
            ok = active & (total > 0)
            along += np.divide(a, total, out=np.zeros(len(X)), where=ok)
            across += np.divide(c, total, out=np.zeros(len(X)), where=ok)
        return along >= across
