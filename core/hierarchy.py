"""The patch hierarchy of hierarchical radiosity: one tree of nodes per surface side.

Each surface side (front, and back when two-sided) gets a tree whose root is the whole surface
and whose leaves are the user's patches: a quadtree over the patch grid (Hanrahan, Salzman &
Aupperle 1991, "A rapid hierarchical radiosity algorithm", SIGGRAPH '91). A node covers a
rectangle of patch cells [i0, i1) x [j0, j1) of the (nu, nv) grid; it splits at the middle of
each range that spans more than one cell, so children number four (or two, along one
parameter, when the other is down to one cell). Every node is a `Surface` (a `subpatch` on the
grid's own parameter lines), so the exact kernels of `transport` apply to any pair of nodes.

Where surfaces touch (a ball resting on a floor, a wall standing on it) the radiosity varies
within a patch far more than between patches elsewhere: the floor under the ball sees almost
only the ball's lowest part, which sees almost only the dark floor, and a patch's mean includes
its brighter rest. So the patches that touch another surface (`touching_patches`) get
`levels` more quadtree levels below them: the links can reach below the user's patches there,
and a patch's result is the area mean of its sub-patches (the tree's pull). Below those levels
the cells are graded toward each patch's point nearest to the surface it touches
(`contact_points`): a ball's underside 0.1 m over a floor sees mostly the floor right under it,
in its shadow, and a floor cell of a fixed fraction of a large patch is mostly lit (a whole
ball as one patch over 3.4 m floor patches came out 2.5-3x too bright at its lowest point).

Where another surface meets a patch along one of its sides (a wall under a ceiling) the light
varies fastest right at the seam; `seam_sides` finds those sides and `GridSplit` grades the cells
toward them (strips that halve in width toward the seam).

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

from . import ragged
from .elements import Elements
from .surface import nearest_step

MOMENT_ORDER = 6  # Gauss points per parameter for the area moments of a node (a smooth density)
CONTACT_LEVELS = 2  # quadtree levels below a user patch that touches another surface
CONTACT_GAP = 2.0  # patches closer than this times the smaller one's bounding radius touch
CONTACT_SIZE = 0.2  # ... and the larger of the two is above this times the smaller surface's size
CONTACT_FACING = 0.5  # ... and their normals meet at more than 120 degrees (a wedge under 60)
CONTACT_REACH = 1.0  # ... and their nearest points are within this times the smaller surface's size
CONTACT_CELL = 0.2  # cells toward a contact point narrow down to this times the smaller surface's size
CONTACT_CELL_GAP = 0.5  # ... or this times the gap there, if larger (the light varies on that scale)
CONTACT_GRADING = 2.0  # ... a cell splitting while its distance to the point is below this times its size
MAX_CONTACT_DEPTH = 10  # at most this many levels below a patch toward a contact point
CONTACT_ORDER = 4  # cells per parameter of a patch searched for its nearest point to another
CONTACT_SEARCH = 10  # ... halving the searched box this many times
PARAMETER_STEPS = 8  # Gauss-Newton steps locating a point's parameters on a node
PARAMETER_SEEDS = 4  # ... from the nearest of this many squared cell centres of the node
SEED_BLOCK = 1 << 15  # points whose seeds are evaluated at once
ROOT_BLOCK = 256  # trees whose pairs `touching_patches` descends at once
SEAM_U0, SEAM_U1, SEAM_V0, SEAM_V1 = 1, 2, 4, 8  # a patch's sides (`GridSplit` seams)
SEAM_GAP = 0.02  # a side within this times its patch's bounding radius of another surface: a seam


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
    """Quadtree over an nu x nv patch grid of a parametric surface, deeper under the patches
    `refined` marks, and graded toward the patch sides `seams` marks.

    Node cell ranges count cells of the fine grid (nu 2^L, nv 2^L, L the deepest patch's
    levels): a user patch is an aligned block of 2^L x 2^L of them, split down to blocks of
    2^(L - its levels). Below that, a cell on a side of its patch that `seams` marks (another
    surface meets the patch there: a wall under a ceiling) is halved across that side `graded`
    more times, so the cells next to the seam narrow geometrically (strips along the seam, a
    graded mesh) while the rest of the patch keeps its cells.

    Parameters
    ----------
    surface : Surface
        The surface side (its `domain` is split on the grid's lines, as `Surface.split` does).
    grid : (int, int)
        The user's (nu, nv).
    refined : ndarray of bool or int, shape (nu * nv,), optional
        Per user patch (i * nv + j): True for `levels` levels of sub-patches, or its own count.
    levels : int
        Quadtree levels below a patch marked True.
    seams : ndarray of int, shape (nu * nv,), optional
        Per user patch, the sides where a seam runs, bits SEAM_U0, SEAM_U1, SEAM_V0, SEAM_V1.
    graded : int
        Halvings toward a marked side below the patch's own levels.
    foci : ContactPoints, optional
        Points of the patches nearest to surfaces they touch: below its own levels a patch's
        cells split toward them (`contact_points`): a cell while it is larger than the point's
        cell size and closer to the point than CONTACT_GRADING times its size (a geometrically
        graded mesh around the contact: O(levels) cells per point where a uniform split to the
        same size takes 4^levels).
    """

    def __init__(self, surface, grid, refined=None, levels=0, seams=None, graded=0, foci=None):
        self.surface = surface
        self.nu, self.nv = grid
        depth = np.zeros(self.nu * self.nv, dtype=np.int64)
        if refined is not None:
            refined = np.asarray(refined).ravel()
            depth = refined * levels if refined.dtype == bool else refined.astype(np.int64)
        self.seams = np.zeros(depth.size, np.int64) if seams is None else np.asarray(seams, np.int64).ravel()
        finest = depth + np.where(self.seams > 0, graded, 0)
        self.foci = {}  # user patch -> (k, 4): s, t (fractions of the patch), cell sizes hs, ht
        deepest = int(finest.max(initial=0))
        if foci is not None:
            for patch in np.unique(foci.patch):
                at = foci.patch == patch
                self.foci[int(patch)] = np.stack([foci.s[at], foci.t[at], foci.hs[at], foci.ht[at]], 1)
            smallest = np.maximum(np.minimum(foci.hs, foci.ht), 2.0**-MAX_CONTACT_DEPTH)
            deepest = max(deepest, int(np.ceil(np.log2(1.0 / smallest.min(initial=1.0)))))
        self.step = 2**deepest
        self.smallest = self.step // 2**depth  # per user patch: its leaves' size in fine cells
        self.finest = self.step // 2**finest  # ... and its cells' at a marked side
        (u0, u1), (v0, v1) = surface.domain
        self.us = np.linspace(u0, u1, self.nu * self.step + 1)
        self.vs = np.linspace(v0, v1, self.nv * self.step + 1)

    def root(self):
        """The whole grid as a cell range (i0, i1, j0, j1)."""
        return (0, self.nu * self.step, 0, self.nv * self.step)

    def children(self, cells):
        """The cell ranges of a node's children (empty for a leaf), list of (i0, i1, j0, j1)."""
        i0, i1, j0, j1 = cells
        S = self.step
        if i1 - i0 > S or j1 - j0 > S:  # above the user's patches: split on their lines
            mu, mv = i0 + (i1 - i0) // S // 2 * S, j0 + (j1 - j0) // S // 2 * S
            us = (i0, mu, i1) if i1 - i0 > S else (i0, i1)
            vs = (j0, mv, j1) if j1 - j0 > S else (j0, j1)
        else:
            index = (i0 // S) * self.nv + j0 // S  # the user patch
            if i1 - i0 > self.smallest[index]:
                us, vs = (i0, (i0 + i1) // 2, i1), (j0, (j0 + j1) // 2, j1)
            else:  # graded toward the patch's contact points and marked sides
                pi, pj, side, fine = i0 // S * S, j0 // S * S, self.seams[index], self.finest[index]
                toward = self.toward_focus(index, (i0 - pi) / S, (i1 - pi) / S, (j0 - pj) / S, (j1 - pj) / S)
                if toward is not None:
                    us = (i0, (i0 + i1) // 2, i1) if toward[0] and i1 - i0 > 1 else (i0, i1)
                    vs = (j0, (j0 + j1) // 2, j1) if toward[1] and j1 - j0 > 1 else (j0, j1)
                    if len(us) + len(vs) > 4:
                        return _products(us, vs)
                across_u = i1 - i0 > fine and (
                    (side & SEAM_U0 and i0 == pi) or (side & SEAM_U1 and i1 == pi + S)
                )
                across_v = j1 - j0 > fine and (
                    (side & SEAM_V0 and j0 == pj) or (side & SEAM_V1 and j1 == pj + S)
                )
                if not (across_u or across_v):
                    return []
                us = (i0, (i0 + i1) // 2, i1) if across_u else (i0, i1)
                vs = (j0, (j0 + j1) // 2, j1) if across_v else (j0, j1)
        return _products(us, vs)

    def toward_focus(self, index, s0, s1, t0, t1):
        """Whether the cell [s0, s1] x [t0, t1] (fractions of user patch `index`) splits toward
        a contact point of the patch, along (u, v): a pair of bools, or None.

        Distances and sizes count in the point's cell sizes (hs, ht: one length on the surface,
        so the test is metric): a cell closer to the point than CONTACT_GRADING times its larger
        size splits along each parameter where it is larger than the cell size."""
        foci = self.foci.get(index)
        if foci is None:
            return None
        s, t, hs, ht = foci.T
        zs, zt = (s1 - s0) / hs, (t1 - t0) / ht
        ds = np.maximum(np.maximum(s0 - s, s - s1), 0.0) / hs
        dt = np.maximum(np.maximum(t0 - t, t - t1), 0.0) / ht
        near = (np.maximum(zs, zt) > 1.0) & (np.hypot(ds, dt) < CONTACT_GRADING * np.maximum(zs, zt))
        if not near.any():
            return None
        return bool(np.any(near & (zs > 1.0))), bool(np.any(near & (zt > 1.0)))

    def patch(self, cells):
        """The user patch index (i * nv + j) of a user patch's range, else -1."""
        i0, i1, j0, j1 = cells
        S = self.step
        return (i0 // S) * self.nv + j0 // S if (i1 - i0 == S and j1 - j0 == S) else -1

    def surface_of(self, cells):
        """The node's patch as a Surface on the grid's parameter lines."""
        i0, i1, j0, j1 = cells
        if cells == self.root():
            return self.surface
        return self.surface.subpatch(u=(self.us[i0], self.us[i1]), v=(self.vs[j0], self.vs[j1]))


def _products(us, vs):
    """The cell ranges (i0, i1, j0, j1) between consecutive cuts us along u and vs along v."""
    return [(a, b, c, d) for a, b in zip(us[:-1], us[1:]) for c, d in zip(vs[:-1], vs[1:])]


def split_for(surface, grid, refined=None, levels=0, seams=None, graded=0, foci=None):
    """The `TreeSplit` of a surface side: its own (`surface.tree_split(grid)`) if its kind has one,
    else a `GridSplit` (`refined` patches `levels` deeper, graded `graded` more toward `seams`
    and toward the contact points `foci`)."""
    own = getattr(surface, "tree_split", None)
    return own(grid) if callable(own) else GridSplit(surface, grid, refined, levels, seams, graded, foci)


class Hierarchy:
    """Nodes of every surface side's tree in flat arrays, with bounds and exact kernels.

    Parameters
    ----------
    sides : sequence of (surface, object, grid, first_element)
        One tree per surface side: the side as a `Surface` (front as front), its scene object,
        its (nu, nv) patch grid and the element number of its patch 0 (the user's patches map
        to the elements `first_element + i * nv + j` of the scene's `Elements`).
    refined : sequence of (ndarray of bool or int, or None), optional
        Per side, the user patches that get `levels` more levels below them (`touching_patches`),
        or each patch's own count of levels (`GridSplit`).
    levels : int
    seams : sequence of (ndarray of int or None), optional
        Per side, each user patch's sides where another surface meets it (`seam_sides`).
    graded : int
        Halvings toward those sides below a patch's own levels (`GridSplit`).
    foci : sequence of (ContactPoints or None), optional
        Per side, points its patches' cells are graded toward (`contact_points`).

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
        The scene element a user patch's node is (-1 above and below the user's patches).
    patch_node : ndarray of int, shape (M,)
        The node of the user patch a node lies in (itself for a patch, -1 above the patches).
    area : ndarray, shape (M,)
    levels : list of ndarray of int
        Nodes of each level, roots first.
    """

    def __init__(self, sides, refined=None, levels=0, seams=None, graded=0, foci=None):
        sides = list(sides)
        refined = [None] * len(sides) if refined is None else list(refined)
        seams = [None] * len(sides) if seams is None else list(seams)
        foci = [None] * len(sides) if foci is None else list(foci)
        splits = [
            split_for(surface, grid, mask, levels, sides_marked, graded, points)
            for (surface, _, grid, _), mask, sides_marked, points in zip(sides, refined, seams, foci)
        ]
        self.sides = sides
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
        self.patch_node = np.where(self.element >= 0, np.arange(M), -1)
        for nodes in levels[1:]:
            below = nodes[self.patch_node[nodes] < 0]
            self.patch_node[below] = self.patch_node[self.parent[below]]
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

    def rule(self, nodes, order):
        """`points` with unit normals and the rule's area weights: points and unit normals,
        shapes (K * q, 3), and weights (K, q) (Gauss weight times area density)."""
        X, normal = self.points(nodes, order)
        length = np.linalg.norm(normal, axis=1)
        N = normal / np.maximum(length, 1e-300)[:, None]
        _, _, w = square_rule(order)
        return X, N, w[None] * length.reshape(-1, w.size)

    def mean(self, coef):
        """Area-weighted mean over each node of quadratics, coefficients (M, 6, C) -> (M, C)."""
        return np.einsum("mkc,mk->mc", coef, self.moments)

    @property
    def leaves(self):
        """Leaf nodes, shape (L,)."""
        return np.flatnonzero(self.child_count == 0)

    @property
    def patch_nodes(self):
        """Nodes of the user's patches, shape (N,)."""
        return np.flatnonzero(self.element >= 0)

    def descend(self, nodes, x):
        """The leaf under each node that holds each point, shape (K,): the point's parameters
        on the node (`parameters_of`), then from a node with children to the child whose
        parameter box holds them.

        Parameters
        ----------
        nodes : ndarray of int, shape (K,)
        x : ndarray, shape (K, 3)
            Points on the nodes.
        """
        nodes = np.array(nodes, dtype=np.int64, copy=True)
        inner = np.flatnonzero(self.child_count[nodes] > 0)
        if inner.size == 0:
            return nodes
        u, v = self.parameters_of(nodes[inner], x[inner])
        while inner.size:
            position, child = self.children(nodes[inner])
            box = self.box[child]
            pu, pv = u[position], v[position]
            # how far outside the child's box the parameters are, relative to its size (0: inside)
            outside = np.maximum.reduce(
                [
                    (box[:, 0] - pu) / (box[:, 1] - box[:, 0]),
                    (pu - box[:, 1]) / (box[:, 1] - box[:, 0]),
                    (box[:, 2] - pv) / (box[:, 3] - box[:, 2]),
                    (pv - box[:, 3]) / (box[:, 3] - box[:, 2]),
                ]
            )
            best = np.full(inner.size, np.inf)
            np.minimum.at(best, position, outside)
            hit = np.flatnonzero(outside <= best[position])[::-1]  # ties: the lower child
            chosen = np.empty(inner.size, dtype=np.int64)
            chosen[position[hit]] = child[hit]
            nodes[inner] = chosen
            more = self.child_count[chosen] > 0
            inner, u, v = inner[more], u[more], v[more]
        return nodes

    def parameters_of(self, nodes, x, steps=PARAMETER_STEPS):
        """Parameters (u, v) of points on nodes, each shape (K,): Gauss-Newton (`nearest_step`)
        from the nearest of PARAMETER_SEEDS^2 cell centres of the node's box, kept inside the box.

        A single start at the box's centre is not enough on a node that turns far: from the
        centre of a whole sphere (azimuth pi) a point at azimuth 0 is a saddle of the distance,
        the steps stall and the point lands in a leaf on the far side (its gather took that
        leaf's links: a band along a sphere's parameter seam came out a third too dark).

        Parameters
        ----------
        nodes : ndarray of int, shape (K,)
        x : ndarray, shape (K, 3)
            Points on (or within rounding of) the nodes.
        """
        e = self.elements
        index = e.index[nodes]
        box = self.box[nodes]
        t = (np.arange(PARAMETER_SEEDS) + 0.5) / PARAMETER_SEEDS
        tu, tv = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
        u, v = np.empty(len(nodes)), np.empty(len(nodes))
        for start in range(0, len(nodes), SEED_BLOCK):  # (bounded memory: seeds x points)
            part = slice(start, start + SEED_BLOCK)
            b = box[part]
            su = b[:, 0, None] + (b[:, 1] - b[:, 0])[:, None] * tu[None]  # (k, seeds)
            sv = b[:, 2, None] + (b[:, 3] - b[:, 2])[:, None] * tv[None]
            seeds, _, _ = e.solver.set.derivatives(np.repeat(index[part], tu.size), su.ravel(), sv.ravel())
            d2 = ((seeds.reshape(len(b), tu.size, 3) - x[part, None]) ** 2).sum(2)
            nearest = np.argmin(d2, 1)[:, None]
            u[part], v[part] = (np.take_along_axis(a, nearest, 1)[:, 0] for a in (su, sv))
        for _ in range(steps):
            du, dv = nearest_step(x, *e.solver.set.derivatives(index, u, v))
            u, v = np.clip(u + du, box[:, 0], box[:, 1]), np.clip(v + dv, box[:, 2], box[:, 3])
        return u, v

    def children(self, nodes):
        """(parent position, child) pairs for the children of `nodes`, shapes (K,) and (K,)."""
        nodes = np.asarray(nodes, dtype=np.int64)
        return ragged.expand(self.first_child[nodes], self.child_count[nodes])

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

    def pull(self, leaf_values, weight=None):
        """Area averages up the trees: inner nodes get the area-weighted mean of their children.

        Parameters
        ----------
        leaf_values : ndarray, shape (M, C)
            Values at leaves (inner rows are ignored).
        weight : ndarray, shape (M,), optional
            Positive weights instead of the areas (the areas of the nodes' free parts: `coverage`).

        Returns
        -------
        ndarray, shape (M, C)
        """
        weight = self.area if weight is None else weight
        out = np.array(leaf_values, dtype=np.float64, copy=True)
        out[self.child_count > 0] = 0.0
        child_area = np.zeros(len(self))
        has = self.parent >= 0
        np.add.at(child_area, self.parent[has], weight[has])
        # deepest level first: a level's nodes are final before their parents are averaged
        for nodes in reversed(self.levels[1:]):
            parents = self.parent[nodes]
            weighted = weight[nodes, None] * out[nodes]
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
            for a in (
                self.parent,
                self.tree,
                self.level,
                self.child_count,
                self.first_child,
                self.element,
                self.patch_node,
            )
        )


def touching_patches(hierarchy, gap=None, facing=None):
    """The user patches of each side that touch a patch of another surface, list of (nu * nv,)
    bool arrays (None where none do).

    Two patches touch when their boxes come closer than `gap` times the smaller one's bounding
    radius, they lie on different geometries (a surface's own neighbours meet at its smooth
    parameter lines), they can exchange light (`Elements.exchange`: not facing away, not flat
    pieces of one plane, not a whole ball's inside and something outside it) and they face each
    other across a narrow wedge at their nearest points (`facing_patches`: a ball resting on a
    floor, near its contact, even when the whole ball is one patch; not the floor's back and the
    ball's inside),
    and the larger of the two patches' bounding radii is above CONTACT_SIZE times the size of the
    smaller surface (the radius of a sphere of its area): finer patches resolve a contact
    themselves (a floor under a ball of radius R against Cycles: floor patches of bounding
    radius 0.18 R and ball rows of 5.6 degrees are within 3.3e-3 of the lit floor's level
    everywhere, as 2 levels below 0.7 R and 22.5 degrees are; 0.35 R and 11 degrees, 1.25e-2).
    Walls meeting at a right angle do not count: their radiosity varies mildly toward the seam
    (per-patch means within 1.1 % of a solve with 3 more levels along every seam of a room,
    against 20 % on the floor under a resting ball and 36 % on the ball). From
    `neighbour_patches`: about the pairs near a contact or seam, not all pairs of patches.
    """
    h = hierarchy
    facing = facing_patches(h, gap) if facing is None else facing
    touching = np.unique(h.element[np.concatenate([facing.a, facing.b])])
    out = []
    for surface, _, (nu, nv), first in h.sides:
        mask = np.zeros(nu * nv, dtype=bool)
        inside = touching[(touching >= first) & (touching < first + nu * nv)]
        mask[inside - first] = True
        out.append(mask if mask.any() else None)
    return out


class Facing:
    """Pairs of user patches that touch (`facing_patches`), with their nearest points.

    Attributes
    ----------
    a, b : ndarray of int, shape (K,)
        The patches' nodes.
    ua, va, ub, vb : ndarray, shape (K,)
        Parameters of the nearest points on a and on b.
    distance : ndarray, shape (K,)
        The distance between them.
    """

    def __init__(self, a, b, ua, va, ub, vb, distance):
        self.a, self.b, self.ua, self.va, self.ub, self.vb = a, b, ua, va, ub, vb
        self.distance = distance

    def __len__(self):
        return self.a.size


def nearest_points(hierarchy, a, b):
    """The nearest points of node pairs: parameters on a and on b, each shape (K,), and their
    distances: the better of `_searched_on`'s searches on a and on b (a projection onto a node
    from far off its surface can stop short of the nearest point: a whole sphere's)."""
    ua, va, ub, vb, d = _searched_on(hierarchy, a, b)
    ub2, vb2, ua2, va2, d2 = _searched_on(hierarchy, b, a)
    other = d2 < d
    return (
        np.where(other, ua2, ua),
        np.where(other, va2, va),
        np.where(other, ub2, ub),
        np.where(other, vb2, vb),
        np.minimum(d, d2),
    )


def _searched_on(hierarchy, a, b):
    """`nearest_points` by a grid search on a: the CONTACT_ORDER^2 cell centres of a box of a's
    parameters, each projected onto b (`parameters_of`: the nearest point of b to it); the box
    closes to the two cells around the best one, CONTACT_SEARCH times (each time half as wide).
    (Alternate projections between the two surfaces would converge only as R / (R + gap) per
    round for a ball of radius R over a floor.)"""
    h = hierarchy
    e = h.elements
    q = CONTACT_ORDER**2
    t = (np.arange(CONTACT_ORDER) + 0.5) / CONTACT_ORDER
    tu, tv = (x.ravel() for x in np.meshgrid(t, t, indexing="ij"))
    full = h.box[a]
    box = full.copy()
    index_a, bb = np.repeat(e.index[a], q), np.repeat(b, q)
    for _ in range(CONTACT_SEARCH + 1):
        span_u, span_v = box[:, 1] - box[:, 0], box[:, 3] - box[:, 2]
        u = (box[:, 0, None] + span_u[:, None] * tu[None]).ravel()
        v = (box[:, 2, None] + span_v[:, None] * tv[None]).ravel()
        P, _, _ = e.solver.set.derivatives(index_a, u, v)
        ub, vb = h.parameters_of(bb, P)
        X, _, _ = e.solver.set.derivatives(e.index[bb], ub, vb)
        d = np.linalg.norm(P - X, axis=1).reshape(-1, q)
        best = np.argmin(d, 1)
        pick = np.arange(a.size), best
        ua, va = u.reshape(-1, q)[pick], v.reshape(-1, q)[pick]
        # the next box: as wide as two cells, about the best cell's centre, inside a's box
        half_u, half_v = span_u / CONTACT_ORDER, span_v / CONTACT_ORDER
        lo_u = np.clip(ua - half_u, full[:, 0], full[:, 1] - 2 * half_u)
        lo_v = np.clip(va - half_v, full[:, 2], full[:, 3] - 2 * half_v)
        box = np.stack([lo_u, lo_u + 2 * half_u, lo_v, lo_v + 2 * half_v], 1)
    return ua, va, ub.reshape(-1, q)[pick], vb.reshape(-1, q)[pick], d[pick]


def facing_patches(hierarchy, gap=None):
    """The user patches that touch (`touching_patches`) as `Facing` pairs.

    Near (`neighbour_patches`) and large (CONTACT_SIZE) pairs whose front normals at their
    nearest points (`nearest_points`) meet at more than arccos(-CONTACT_FACING), those points
    within CONTACT_REACH of the smaller surface's size, each bounding centre in front of the
    other's normal there. Normals at the nearest points, not the patches'
    mean normals: a whole ball as one patch has no mean normal, but faces the floor at its foot.
    """
    h = hierarchy
    e = h.elements
    a, b = neighbour_patches(h, gap)
    # patches already small beside the surfaces they touch resolve the contact themselves
    size = surface_sizes(h)
    large = np.maximum(e.radius[a], e.radius[b]) > CONTACT_SIZE * np.minimum(size[a], size[b])
    # ... and pairs whose normal cones cannot face each other (walls at a seam) need no search
    axis, half = e.solver.axis[e.solver.slot], e.solver.half_angle[e.solver.slot]
    between = np.arccos(np.clip(np.einsum("ki,ki->k", axis[a], axis[b]), -1.0, 1.0))
    may_face = between + half[a] + half[b] >= np.arccos(-CONTACT_FACING)
    a, b = a[large & may_face], b[large & may_face]
    ua, va, ub, vb, distance = nearest_points(h, a, b)
    _, na = e.solver.set.evaluate(e.index[a], ua, va)
    _, nb = e.solver.set.evaluate(e.index[b], ub, vb)
    na /= np.maximum(np.linalg.norm(na, axis=1), 1e-300)[:, None]
    nb /= np.maximum(np.linalg.norm(nb, axis=1), 1e-300)[:, None]
    # facing across a narrow wedge (a ball on a floor), not meeting at a wide angle (walls), each
    # centre in front of the other's normal (a floor's back and a ball's inside also face each
    # other, from the wrong sides)
    facing = np.einsum("ki,ki->k", na, nb) <= -CONTACT_FACING
    # ... and no farther apart than CONTACT_REACH times the smaller surface's size (a whole ball
    # as one patch has a bounding radius of several times its own: `neighbour_patches` lets it in)
    facing &= distance <= CONTACT_REACH * np.minimum(size[a], size[b])
    offset = e.center[b] - e.center[a]
    facing &= (np.einsum("ki,ki->k", na, offset) > 0) & (np.einsum("ki,ki->k", nb, offset) < 0)
    return Facing(a[facing], b[facing], ua[facing], va[facing], ub[facing], vb[facing], distance[facing])


def surface_sizes(hierarchy):
    """The size of each node's surface side: the radius of a sphere of its area, shape (M,)."""
    h = hierarchy
    return np.sqrt(h.area[h.roots[h.tree]] / (4.0 * np.pi))


class ContactPoints:
    """Points of one side's user patches nearest to surfaces they touch (`contact_points`).

    Attributes
    ----------
    patch : ndarray of int, shape (F,)
        User patch (i * nv + j) of each point.
    s, t : ndarray, shape (F,)
        The point in fractions of its patch's parameter ranges (0 .. 1).
    hs, ht : ndarray, shape (F,)
        The cell size toward the point (CONTACT_CELL times the smaller surface's size) in
        fractions of the patch's ranges along u and v.
    """

    def __init__(self, patch, s, t, hs, ht):
        self.patch, self.s, self.t, self.hs, self.ht = patch, s, t, hs, ht

    def __len__(self):
        return self.patch.size


def contact_points(hierarchy, gap=None, facing=None):
    """Per side, the points of its touching patches nearest to each surface they touch
    (`ContactPoints`, or None): where a ball rests on (or hangs just over) a floor, the floor's
    light varies on the scale of the gap and the ball's size around the point under it, and the
    ball's underside sees mostly that spot, so cells are graded toward it (`GridSplit`) down to
    CONTACT_CELL times the smaller surface's size, or CONTACT_CELL_GAP times the gap at the
    point if that is larger (the light varies on the scale of the gap: a patch beside the one
    under the ball has its nearest point farther off, and gets coarser cells there).

    From the touching pairs' nearest points (`facing_patches`, `nearest_points`); one point per
    patch and other surface (the nearest).
    """
    h = hierarchy
    e = h.elements
    f = facing_patches(h, gap) if facing is None else facing
    out = [None] * len(h.sides)
    if len(f) == 0:
        return out
    receiver, other = np.concatenate([f.a, f.b]), np.concatenate([f.b, f.a])
    u, v = np.concatenate([f.ua, f.ub]), np.concatenate([f.va, f.vb])
    d = np.concatenate([f.distance, f.distance])
    # one point per patch and touching surface: the nearest of its pairs
    key = receiver * (int(e.geometry.max()) + 1) + e.geometry[other]
    order = np.lexsort((d, key))
    first = order[np.r_[True, key[order][1:] != key[order][:-1]]]
    receiver, other, u, v, d = receiver[first], other[first], u[first], v[first], d[first]
    size = surface_sizes(h)
    cell = np.maximum(CONTACT_CELL * np.minimum(size[receiver], size[other]), CONTACT_CELL_GAP * d)
    box = h.box[receiver]
    span_u, span_v = box[:, 1] - box[:, 0], box[:, 3] - box[:, 2]
    # the patch's lengths along u and v (at the point and its centre: a pole has none along v)
    length_u, length_v = np.zeros(receiver.size), np.zeros(receiver.size)
    for pu, pv in ((u, v), (box[:, 0] + 0.5 * span_u, box[:, 2] + 0.5 * span_v)):
        _, du, dv = e.solver.set.derivatives(e.index[receiver], pu, pv)
        length_u = np.maximum(length_u, np.linalg.norm(du, axis=1) * span_u)
        length_v = np.maximum(length_v, np.linalg.norm(dv, axis=1) * span_v)
    s, t = (u - box[:, 0]) / span_u, (v - box[:, 2]) / span_v
    hs, ht = cell / np.maximum(length_u, 1e-300), cell / np.maximum(length_v, 1e-300)
    first_element = np.array([first for (_, _, _, first) in h.sides])
    side = h.tree[receiver]
    patch = h.element[receiver] - first_element[side]
    for k in np.unique(side):
        at = side == k
        out[k] = ContactPoints(patch[at], s[at], t[at], hs[at], ht[at])
    return out


def neighbour_patches(hierarchy, gap=None):
    """Pairs of user patches (their nodes a, b, each shape (K,)) of different geometries whose
    boxes come closer than `gap` (default CONTACT_GAP) times the smaller one's bounding radius
    and that can exchange light (`Elements.exchange`): a seam between walls, a ball on a floor.
    A point of one gathers the other's radiosity from close by. Found by descending all pairs of
    trees at once (a node's box holds its children's)."""
    gap = CONTACT_GAP if gap is None else gap
    roots = hierarchy.roots
    found = [(np.zeros(0, np.int64), np.zeros(0, np.int64))]
    for start in range(0, roots.size, ROOT_BLOCK):  # (a mesh is one tree per piece: many roots)
        a = np.repeat(np.arange(start, min(start + ROOT_BLOCK, roots.size)), roots.size)
        b = np.tile(np.arange(roots.size), a.size // max(roots.size, 1))
        keep = a < b
        found += _neighbour_pairs(hierarchy, roots[a[keep]], roots[b[keep]], gap)
    a, b = (np.concatenate(x) for x in zip(*found))
    return a, b


def _neighbour_pairs(h, a, b, gap):
    """`neighbour_patches`' descent from node pairs (a, b): list of (a, b) user patch pairs."""
    e = h.elements
    found = []
    while a.size:
        pad = gap * np.minimum(e.radius[a], e.radius[b])
        near = np.all(
            (e.box_min[a] - pad[:, None] <= e.box_max[b]) & (e.box_min[b] - pad[:, None] <= e.box_max[a]), 1
        )
        near &= e.geometry[a] != e.geometry[b]
        a, b = a[near], b[near]
        # pairs that exchange no light (facing away, coplanar, a ball's inside and the outside;
        # bounds hold for descendants)
        alive = e.exchange(a, b)
        a, b = a[alive], b[alive]
        user = (h.element[a] >= 0) & (h.element[b] >= 0)
        found.append((a[user], b[user]))
        a, b = a[~user], b[~user]
        # split the node above the user's patches, the larger of two such
        split_a = (h.element[a] < 0) & ((h.element[b] >= 0) | (e.radius[a] >= e.radius[b]))
        pa, ca = h.children(a[split_a])
        pb, cb = h.children(b[~split_a])
        a = np.concatenate([ca, a[~split_a][pb]])
        b = np.concatenate([b[split_a][pa], cb])
    return found


def seam_sides(hierarchy, nodes, gap=SEAM_GAP, pairs=None):
    """Which sides of user patches lie on another surface beside the patches `nodes` (a wall's
    top under a ceiling), on both sides of each such seam: shape (M,) int of SEAM_U0 | SEAM_U1 |
    SEAM_V0 | SEAM_V1 bits per node (0 off the user patches).

    A side of a patch counts when one of its points at a quarter, half and three quarters of its
    length lies within `gap` times the patch's bounding radius of the box of a neighbouring patch
    (`pairs`, default `neighbour_patches`: another geometry, exchanging light), one of the two in
    `nodes`.
    """
    h = hierarchy
    e = h.elements
    out = np.zeros(len(h), dtype=np.int64)
    a, b = neighbour_patches(h) if pairs is None else pairs
    a, b = np.concatenate([a, b]), np.concatenate([b, a])
    chosen = np.zeros(len(h), dtype=bool)
    chosen[np.asarray(nodes, dtype=np.int64)] = True
    keep = chosen[a] | chosen[b]
    a, b = a[keep], b[keep]
    t = np.array([0.25, 0.5, 0.75])
    u0, u1, v0, v1 = (x[:, None] for x in e.boxes_of(a).T)
    su, sv = u0 + t * (u1 - u0), v0 + t * (v1 - v0)  # (K, 3)
    lo, hi = e.box_min[b][:, None], e.box_max[b][:, None]
    for bit, u, v in (
        (SEAM_U0, np.broadcast_to(u0, sv.shape), sv),
        (SEAM_U1, np.broadcast_to(u1, sv.shape), sv),
        (SEAM_V0, su, np.broadcast_to(v0, su.shape)),
        (SEAM_V1, su, np.broadcast_to(v1, su.shape)),
    ):
        x, _ = e.solver.set.evaluate(np.repeat(e.index[a], t.size), u.ravel(), v.ravel())
        x = x.reshape(a.size, t.size, 3)
        distance = np.linalg.norm(np.maximum(np.maximum(lo - x, x - hi), 0.0), axis=-1).min(1)
        np.bitwise_or.at(out, a, np.where(distance <= gap * e.radius[a], bit, 0))
    return out
