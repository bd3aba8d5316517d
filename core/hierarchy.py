"""The patch hierarchy of hierarchical radiosity: one tree of nodes per surface side.

Each surface side (front, and back when two-sided) gets a tree whose root is the whole surface
and whose leaves are the user's patches: a quadtree over the patch grid (Hanrahan, Salzman &
Aupperle 1991, "A rapid hierarchical radiosity algorithm", SIGGRAPH '91). A node covers a
rectangle of patch cells [i0, i1) x [j0, j1) of the (nu, nv) grid; it splits at the middle of
each range that spans more than one cell, so children number four (or two, along one
parameter, when the other is down to one cell). Every node is a `Surface` (a `subpatch` on the
grid's own parameter lines), so the exact kernels of `transport` apply to any pair of nodes.

How a tree splits is a `TreeSplit`: `GridSplit` is the one for parametric surfaces; a kind with
its own structure (a polygon mesh's tree over faces, from its BVH) provides another by giving
the surface a `tree_split()` method that returns one (`split_for`).

All nodes of all trees are stored in flat arrays, ordered by level (roots first), so parents
come before their children and push/pull run level by level.

Quantities that vary over a node (a link's point-to-source factor) are quadratics in the node's
normalised parameters (t_u, t_v) in [-1, 1]^2, coefficients (1, t_u, t_v, t_u^2, t_v^2, t_u t_v):
`push_quadratic` re-expresses a parent's quadratic in each child's parameters (an affine map).
"""

import numpy as np

from .elements import Elements

MOMENT_ORDER = 6  # Gauss points per parameter for the area moments of a node (a smooth density)


def square_rule(order):
    """Gauss-Legendre rule on [-1, 1]^2 in a node's normalised parameters: t_u, t_v and weights,
    each shape (order^2,) (u-major)."""
    t, w = np.polynomial.legendre.leggauss(order)
    tu, tv = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
    return tu, tv, np.outer(w, w).ravel()


def quadratic_basis(tu, tv):
    """The basis (1, t_u, t_v, t_u^2, t_v^2, t_u t_v) at points, shape (q, 6)."""
    return np.stack([np.ones_like(tu), tu, tv, tu * tu, tv * tv, tu * tv], 1)


class GridSplit:
    """Quadtree over an nu x nv patch grid of a parametric surface.

    Parameters
    ----------
    surface : Surface
        The surface side (its `domain` is split on the grid's lines, as `Surface.split` does).
    grid : (int, int)
        The user's (nu, nv).
    """

    def __init__(self, surface, grid):
        self.surface = surface
        self.nu, self.nv = grid
        (u0, u1), (v0, v1) = surface.domain
        self.us = np.linspace(u0, u1, self.nu + 1)
        self.vs = np.linspace(v0, v1, self.nv + 1)

    def root(self):
        """The whole grid as a cell range (i0, i1, j0, j1)."""
        return (0, self.nu, 0, self.nv)

    def children(self, cells):
        """The cell ranges of a node's children (empty for one patch), list of (i0, i1, j0, j1)."""
        i0, i1, j0, j1 = cells
        us = (i0, (i0 + i1) // 2, i1) if i1 - i0 > 1 else (i0, i1)
        vs = (j0, (j0 + j1) // 2, j1) if j1 - j0 > 1 else (j0, j1)
        if len(us) == 2 and len(vs) == 2:
            return []
        return [(a, b, c, d) for a, b in zip(us[:-1], us[1:]) for c, d in zip(vs[:-1], vs[1:])]

    def patch(self, cells):
        """The user patch index (i * nv + j) of a one-cell range, else -1."""
        i0, i1, j0, j1 = cells
        return i0 * self.nv + j0 if (i1 - i0 == 1 and j1 - j0 == 1) else -1

    def surface_of(self, cells):
        """The node's patch as a Surface on the grid's parameter lines."""
        i0, i1, j0, j1 = cells
        if cells == self.root():
            return self.surface
        return self.surface.subpatch(u=(self.us[i0], self.us[i1]), v=(self.vs[j0], self.vs[j1]))


def split_for(surface, grid):
    """The `TreeSplit` of a surface side: its own (`surface.tree_split(grid)`) if its kind has one,
    else a `GridSplit`."""
    own = getattr(surface, "tree_split", None)
    return own(grid) if callable(own) else GridSplit(surface, grid)


class Hierarchy:
    """Nodes of every surface side's tree in flat arrays, with bounds and exact kernels.

    Parameters
    ----------
    sides : sequence of (surface, object, grid, first_element)
        One tree per surface side: the side as a `Surface` (front as front), its scene object,
        its (nu, nv) patch grid and the element number of its patch 0 (the leaves map to the
        elements `first_element + i * nv + j` of the scene's `Elements`).

    Attributes
    ----------
    elements : Elements
        The nodes as elements (node n is element n): bounds, areas, orders and point-to-patch
        integrals, so `transport.pair_form_factors` and `pair_visibility` take node pairs.
    parent : ndarray of int, shape (M,)
        Parent node (-1 for roots).
    first_child, child_count : ndarray of int, shape (M,)
        Children are nodes first_child .. first_child + child_count - 1 (count 0: a leaf).
    level : ndarray of int, shape (M,)
        Depth below the tree's root.
    tree : ndarray of int, shape (M,)
        The side (index into `sides`) a node belongs to.
    element : ndarray of int, shape (M,)
        The scene element a leaf is (-1 for inner nodes).
    area : ndarray, shape (M,)
    levels : list of ndarray of int
        Nodes of each level, roots first.
    """

    def __init__(self, sides):
        sides = list(sides)
        splits = [split_for(surface, grid) for surface, _, grid, _ in sides]
        # breadth first: every level's nodes after the previous level's
        frontier = [(t, split.root(), -1) for t, split in enumerate(splits)]
        cells, parent, tree, level, levels = [], [], [], [], []
        depth = 0
        while frontier:
            start = len(cells)
            levels.append(np.arange(start, start + len(frontier)))
            nxt = []
            for k, (t, c, p) in enumerate(frontier):
                cells.append(c)
                parent.append(p)
                tree.append(t)
                level.append(depth)
                for child in splits[t].children(c):
                    nxt.append((t, child, start + k))
            frontier = nxt
            depth += 1
        M = len(cells)
        self.parent = np.array(parent, dtype=np.int64)
        self.tree = np.array(tree, dtype=np.int64)
        self.level = np.array(level, dtype=np.int64)
        self.levels = levels
        self.child_count = np.bincount(self.parent[self.parent >= 0], minlength=M).astype(np.int64)
        self.first_child = np.full(M, -1, dtype=np.int64)
        has_parent = np.flatnonzero(self.parent >= 0)
        # children of one parent are consecutive (appended together): the first is the smallest
        first = np.full(M, M, dtype=np.int64)
        np.minimum.at(first, self.parent[has_parent], has_parent)
        self.first_child = np.where(self.child_count > 0, first, -1)
        self.element = np.array(
            [(sides[t][3] + p) if (p := splits[t].patch(c)) >= 0 else -1 for t, c in zip(tree, cells)],
            dtype=np.int64,
        )
        surfaces = [splits[t].surface_of(c) for t, c in zip(tree, cells)]
        self.object = np.array([sides[t][1] for t in tree], dtype=np.int64)
        self.elements = Elements(surfaces, self.object)
        self.area = self.elements.area
        self.roots = levels[0]
        self.moments = self._moments()
        # each node's parameter box and its place in its parent's normalised parameters
        self.box = np.array([[*x.domain[0], *x.domain[1]] for x in surfaces], dtype=np.float64)
        self.local = np.tile([0.0, 1.0, 0.0, 1.0], (M, 1))  # (mu, hu, mv, hv): t_parent = m + h t
        child = np.flatnonzero(self.parent >= 0)
        pb, cb = self.box[self.parent[child]], self.box[child]
        for k, (a, b) in enumerate(((0, 1), (2, 3))):
            half = 0.5 * (pb[:, b] - pb[:, a])
            self.local[child, 2 * k] = (0.5 * (cb[:, a] + cb[:, b]) - 0.5 * (pb[:, a] + pb[:, b])) / half
            self.local[child, 2 * k + 1] = 0.5 * (cb[:, b] - cb[:, a]) / half

    def __len__(self):
        return len(self.parent)

    def _moments(self):
        """Area-weighted means over every node of the quadratic basis (1, t_u, t_v, t_u^2, t_v^2,
        t_u t_v) in its normalised parameters, shape (M, 6): a quadratic's mean over the node is
        its coefficients dotted with them (parameters are not uniform in area on curved
        surfaces: a sphere patch's area density goes with the cosine of its latitude)."""
        tu, tv, w = square_rule(MOMENT_ORDER)
        _, normal = self.points(np.arange(len(self)), MOMENT_ORDER)
        weight = w[None] * np.linalg.norm(normal, axis=-1).reshape(-1, tu.size)
        return (weight @ quadratic_basis(tu, tv)) / np.maximum(weight.sum(1), 1e-300)[:, None]

    def points(self, nodes, order):
        """The `square_rule(order)` points of nodes mapped onto their surfaces: points and
        unnormalised normals (area densities), shapes (K * q, 3) each, node by node."""
        e = self.elements
        tu, tv, _ = square_rule(order)
        box = e.solver.set.boxes[e.index[nodes]]  # (K, 4): u0, u1, v0, v1
        u = 0.5 * (box[:, :1] + box[:, 1:2]) + 0.5 * (box[:, 1:2] - box[:, :1]) * tu[None]
        v = 0.5 * (box[:, 2:3] + box[:, 3:4]) + 0.5 * (box[:, 3:4] - box[:, 2:3]) * tv[None]
        return e.solver.set.evaluate(np.repeat(e.index[nodes], tu.size), u.ravel(), v.ravel())

    def mean(self, coef):
        """Area-weighted mean over each node of quadratics, coefficients (M, 6, C) -> (M, C)."""
        return np.einsum("mkc,mk->mc", coef, self.moments)

    @property
    def leaves(self):
        """Leaf nodes, shape (L,)."""
        return np.flatnonzero(self.child_count == 0)

    def children(self, nodes):
        """(parent position, child) pairs for the children of `nodes`, shapes (K,) and (K,)."""
        nodes = np.asarray(nodes, dtype=np.int64)
        count = self.child_count[nodes]
        position = np.repeat(np.arange(nodes.size), count)
        offset = np.arange(position.size) - np.repeat(np.cumsum(count) - count, count)
        return position, np.repeat(self.first_child[nodes], count) + offset

    def push(self, values):
        """Add every node's value to all its descendants (top-down), shape of `values` (M, ...)."""
        out = np.array(values, dtype=np.float64, copy=True)
        for nodes in self.levels[1:]:
            out[nodes] += out[self.parent[nodes]]
        return out

    def push_quadratic(self, coef):
        """Add every node's quadratic to all its descendants, each in its own parameters.

        With t_parent = m + h t_child per parameter, c0 + cu u + cv v + cuu u^2 + cvv v^2 + cuv u v
        becomes a quadratic in the child's (u, v) with the coefficients below.

        Parameters
        ----------
        coef : ndarray, shape (M, 6, C)

        Returns
        -------
        ndarray, shape (M, 6, C)
        """
        out = np.array(coef, dtype=np.float64, copy=True)
        for nodes in self.levels[1:]:
            c0, cu, cv, cuu, cvv, cuv = np.moveaxis(out[self.parent[nodes]], 1, 0)
            mu, hu, mv, hv = (self.local[nodes, k, None] for k in range(4))
            out[nodes, 0] += c0 + cu * mu + cv * mv + cuu * mu * mu + cvv * mv * mv + cuv * mu * mv
            out[nodes, 1] += hu * (cu + 2.0 * cuu * mu + cuv * mv)
            out[nodes, 2] += hv * (cv + 2.0 * cvv * mv + cuv * mu)
            out[nodes, 3] += cuu * hu * hu
            out[nodes, 4] += cvv * hv * hv
            out[nodes, 5] += cuv * hu * hv
        return out

    def pull(self, leaf_values):
        """Area averages up the trees: inner nodes get the area-weighted mean of their children.

        Parameters
        ----------
        leaf_values : ndarray, shape (M, C)
            Values at leaves (inner rows are ignored).

        Returns
        -------
        ndarray, shape (M, C)
        """
        out = np.array(leaf_values, dtype=np.float64, copy=True)
        out[self.child_count > 0] = 0.0
        child_area = np.zeros(len(self))
        has = self.parent >= 0
        np.add.at(child_area, self.parent[has], self.area[has])
        # deepest level first: a level's nodes are final before their parents are averaged
        for nodes in reversed(self.levels[1:]):
            parents = self.parent[nodes]
            weighted = self.area[nodes, None] * out[nodes]
            for c in range(out.shape[1]):
                out[:, c] += np.bincount(parents, weighted[:, c], minlength=len(self))
            done = np.unique(parents)
            out[done] /= child_area[done, None]
        return out

    def spread(self, values):
        """Largest minus smallest child value of each node per channel (0 at leaves), shape (M, C)."""
        values = np.asarray(values, dtype=np.float64)
        hi = np.full(values.shape, -np.inf)
        lo = np.full(values.shape, np.inf)
        child = np.flatnonzero(self.parent >= 0)
        np.maximum.at(hi, self.parent[child], values[child])
        np.minimum.at(lo, self.parent[child], values[child])
        return np.where(np.isfinite(hi) & np.isfinite(lo), hi - lo, 0.0)

    def nbytes(self):
        return sum(
            a.nbytes
            for a in (self.parent, self.tree, self.level, self.child_count, self.first_child, self.element)
        )
