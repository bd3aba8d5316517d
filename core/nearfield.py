"""Near-field final gather: the light of nearby patches resolved across them.

A gather (`Solution.radiosity_at`) sums F(x -> j) V(x, j) B_j over the elements j, each with its
one solved radiosity B_j. Where x lies close to a large element compared with its size (the
underside of a ball hanging a few centimetres over a floor of metre-sized patches), x sees mostly
a small part of j, and the light there can be far from j's mean (the ball's own shadow on the
floor under it): the constant B_j is then wrong by up to the whole contrast of the element.

The final gather of Lischinski, Tampieri & Greenberg ("Combining hierarchical radiosity and
discontinuity meshing", SIGGRAPH 1993, section 6) answers this by gathering again at the points
of the element that x sees. Here that is done as a small radiosity system of its own:

- **near**: a (point, element) pair whose point lies within NEAR_RATIO times the element's
  size (half its box's diagonal) of its box (`near_pairs`);
- **nodes**: each near element's parameter box is cut into cells graded toward the points near
  it (a cell is halved while its radius exceeds GRADE times its distance from the nearest of
  them, down to MAX_DEPTH halvings, at most MAX_NODES cells), with ORDER x ORDER Gauss nodes in
  each (`graded_nodes`). Nodes are themselves points near other elements (the floor under a
  ball is near the ball), so the node sets are graded once more toward each other's nodes
  (ROUNDS);
- **coupling**: a point's (or node's) term F(x -> j) V(x, j) B_j becomes F V sum_c w_c B(y_c) over
  j's nodes, with w_c the point-to-node kernel times the node's area weight, normalised over the
  nodes (`node_weights`): the exact F V of the pair stays, the nodes share it out;
- **solve**: every node gathers the rest of the scene (far elements at their B_j, lights, sky)
  once; the nodes' radiosities then follow from B = E + rho (far + C B), C the couplings between
  nodes, by Jacobi sweeps until no node moves by more than tol of its value (`solve_nodes`):
  light bouncing between a ball and the floor under it is resolved on both.

The arriving light of the points is then their far light plus their couplings to the solved
nodes. Everything is linear in the elements' radiosities, emissions and light powers except
through the reflectances of the near surfaces, so a relight keeps the pieces (`NearTerms`) and
solves the nodes again (`Solution.radiosity_from`).
"""

import numpy as np

from .bounds import lengths, unit_vectors
from .gathered import GatherFactors
from .transport import point_rule

NEAR_RATIO = 1.0  # a point within this times an element's size (`_size`) of its box is near
GRADE = 0.5  # a node's cell radius is at most this times its distance from the nearest near point
MAX_DEPTH = 6  # halvings of an element's parameter box toward near points
MAX_CELLS = 256  # cells an element may get (leaves and their ancestors)
START_SPLITS = 2  # cells per parameter an element starts from
ORDER = 2  # Gauss nodes per parameter in each cell
ROUNDS = 2  # node sets graded toward the points, then toward the points and each other's nodes
MAX_SWEEPS = 200  # Jacobi sweeps of the node system


def near_pairs(elements, x, k, j, F):
    """Which (point, element) pairs of a gather are near, shape (P,) bool: F > 0 and the point
    x_k within NEAR_RATIO times element j's size (half its box's diagonal) of its box."""
    e = elements
    gap = lengths(np.clip(x[k], e.box_min[j], e.box_max[j]) - x[k])
    return (F > 0.0) & (gap < NEAR_RATIO * _size(e, j))


def _size(elements, j):
    """Half the diagonal of elements' boxes, shape (K,): their size for `near_pairs` (a bounding
    radius can be far larger: a whole sphere's)."""
    return 0.5 * lengths(elements.box_max[j] - elements.box_min[j])


def graded_cells(elements, element, points):
    """A quadtree of parameter cells on `element` graded toward `points` (see the module
    docstring): every cell made, leaves and their ancestors.

    Parameters
    ----------
    elements : Elements
    element : int
    points : ndarray, shape (P, 3)
        The points near the element.

    Returns
    -------
    boxes : ndarray, shape (C, 4)
        Cells (u0, u1, v0, v1); the first START_SPLITS^2 are the roots.
    parent : ndarray of int, shape (C,)
        -1 for roots.
    first_child : ndarray of int, shape (C,)
        The first of a cell's four consecutive children, -1 for leaves.
    """
    e = elements
    u0, u1, v0, v1 = e.boxes_of([element])[0]
    s = np.arange(START_SPLITS + 1) / START_SPLITS
    us, vs = u0 + (u1 - u0) * s, v0 + (v1 - v0) * s
    a, b = (i.ravel() for i in np.meshgrid(np.arange(START_SPLITS), np.arange(START_SPLITS), indexing="ij"))
    boxes = [np.stack([us[a], us[a + 1], vs[b], vs[b + 1]], 1)]
    parents = [np.full(a.size, -1)]
    firsts = []
    offset, total = 0, a.size
    for depth in range(MAX_DEPTH + 1):
        live = boxes[-1]
        centre, radius = cell_balls(e, np.full(len(live), element), live)
        gap = np.maximum(_nearest(centre, points) - radius, 0.0)
        split = radius > GRADE * gap
        room = MAX_CELLS - total
        if depth == MAX_DEPTH or room < 4:
            split[:] = False
        elif 4 * np.count_nonzero(split) > room:  # the nearest cells first, within the budget
            order = np.argsort(np.where(split, gap, np.inf))
            split[order[room // 4 :]] = False
        index = np.flatnonzero(split)
        first = np.full(len(live), -1)
        first[index] = offset + len(live) + 4 * np.arange(index.size)
        firsts.append(first)
        offset += len(live)
        if index.size == 0:
            break
        b = live[index]
        um, vm = 0.5 * (b[:, 0] + b[:, 1]), 0.5 * (b[:, 2] + b[:, 3])
        children = np.stack(
            [
                np.stack([b[:, 0], um, b[:, 2], vm], 1),
                np.stack([b[:, 0], um, vm, b[:, 3]], 1),
                np.stack([um, b[:, 1], b[:, 2], vm], 1),
                np.stack([um, b[:, 1], vm, b[:, 3]], 1),
            ],
            1,
        ).reshape(-1, 4)
        boxes.append(children)
        parents.append(np.repeat(offset - len(live) + index, 4))
        total += len(children)
    return np.concatenate(boxes), np.concatenate(parents), np.concatenate(firsts)


def _nearest(centre, points):
    """Distance from each centre (C, 3) to the nearest of `points` (P, 3), shape (C,)."""
    block = max(1, 2_000_000 // max(len(centre), 1))
    gap = np.full(len(centre), np.inf)
    for start in range(0, len(points), block):  # (centres x points, in blocks)
        d = centre[:, None] - points[None, start : start + block]
        gap = np.minimum(gap, np.sqrt(np.einsum("cpi,cpi->cp", d, d)).min(1))
    return gap


def cell_balls(elements, element, boxes):
    """Bounding balls of parameter cells of elements: centres (C, 3) and radii (C,)."""
    hull, margin = elements.cell_hulls(element, boxes)  # (C, 9, 3)
    centre = hull.mean(1)
    return centre, lengths(hull - centre[:, None]).max(1) + margin


class NodeCells:
    """The graded cells of every near element, one array each (`graded_cells` concatenated),
    with ORDER x ORDER Gauss nodes in every cell (for the kernel) and one node at each leaf's
    centre (the unknowns: radiosity varies more slowly across a leaf than the kernel near a point).

    Attributes
    ----------
    element, parent, first_child : ndarray of int, shape (C,)
    centre, radius : ndarray, shape (C, 3) and (C,)
    gauss : (y (C, G, 3), normal (C, G, 3), w (C, G))
        Every cell's Gauss nodes (points, unnormalised normals, parameter weights).
    roots : dict
        element -> its root cells (ndarray of int).
    node_cell : ndarray of int, shape (Q,)
        The leaf of each node.
    y, normal, area : ndarray, shape (Q, 3), (Q, 3), (Q,)
        Nodes, unnormalised front normals and their leaves' areas.
    mean : (cell, node, weight)
        Each cell's area mean over the nodes of its leaves, as sparse entries.
    """

    def __init__(self, elements, targets):
        e = elements
        parts, roots, offset = [], {}, 0
        for q, points in targets:
            boxes, parent, first = graded_cells(e, q, points)
            parts.append((np.full(len(boxes), q), boxes, np.where(parent >= 0, parent + offset, -1),
                          np.where(first >= 0, first + offset, -1)))
            roots[q] = offset + np.arange(START_SPLITS * START_SPLITS)
            offset += len(boxes)
        self.element, boxes, self.parent, self.first_child = (np.concatenate(p) for p in zip(*parts))
        self.roots = roots
        self.centre, self.radius = cell_balls(e, self.element, boxes)
        self.gauss = e.cell_nodes(self.element, boxes, ORDER)
        leaf = np.flatnonzero(self.first_child < 0)
        self.node_cell = leaf
        y, normal, _ = e.cell_nodes(self.element[leaf], boxes[leaf], 1)
        self.y, self.normal = y[:, 0], normal[:, 0]
        self.area = np.einsum("cg,cg->c", lengths(self.gauss[1][leaf]), self.gauss[2][leaf])
        # cell means: every node counts in its leaf and each ancestor
        cell, node = [], []
        at, nodes = self.node_cell.copy(), np.arange(self.node_cell.size)
        while at.size:
            cell.append(at)
            node.append(nodes)
            up = self.parent[at] >= 0
            at, nodes = self.parent[at[up]], nodes[up]
        cell, node = np.concatenate(cell), np.concatenate(node)
        total = np.bincount(cell, self.area[node], minlength=len(self.element))
        self.mean = (cell, node, self.area[node] / total[cell])

    def __len__(self):
        return self.node_cell.size

    def cut(self, x, n, element):
        """Each query's view of its element's cells: the coarsest cells whose radius is at most
        GRADE times their distance from the query point (or leaves), weighted by the point's
        kernel over them (Gauss nodes of each cell), normalised over the query.

        Parameters
        ----------
        x, n : ndarray, shape (P, 3)
            Query points and unit normals.
        element : ndarray of int, shape (P,)
            An element with cells, per query.

        Returns
        -------
        query, cell : ndarray of int, shape (Z,)
        share : ndarray, shape (Z,)
            Summing to 1 over each query's entries.
        has : ndarray of bool, shape (P,)
            Queries whose point sees any of the cells (the others get no entries).
        """
        P = len(x)
        R = START_SPLITS * START_SPLITS
        query = np.repeat(np.arange(P), R)
        cell = np.concatenate([self.roots[q] for q in element]) if P else np.zeros(0, np.int64)
        found_q, found_c = [], []
        while query.size:
            gap = np.maximum(lengths(x[query] - self.centre[cell]) - self.radius[cell], 0.0)
            accept = (self.first_child[cell] < 0) | (self.radius[cell] <= GRADE * gap)
            found_q.append(query[accept])
            found_c.append(cell[accept])
            query, cell = query[~accept], cell[~accept]
            query = np.repeat(query, 4)
            cell = (self.first_child[cell][:, None] + np.arange(4)).ravel()
        query, cell = np.concatenate(found_q), np.concatenate(found_c)
        value = np.empty(query.size)
        y, normal, w = self.gauss
        for s in range(0, query.size, 100_000):
            part = slice(s, s + 100_000)
            q, c = query[part], cell[part]
            value[part] = point_rule(x[q], n[q], y[c], normal[c], w[c])
        total = np.bincount(query, weights=value, minlength=P)
        has = total > 0.0
        keep = has[query] & (value > 0.0)
        query, cell, value = query[keep], cell[keep], value[keep]
        return query, cell, value / total[query], has



class NodeSystem:
    """The linear system of the nodes: B = base + rho (S M (B - offset)), with M the cells'
    area means of the nodes (`NodeCells.mean`) and S each node's couplings to cells.

    Parameters
    ----------
    coupling : (node, cell, value), each shape (Z,)
        S: node gets value times the mean of the cell.
    mean : (cell, node, weight)
        M.
    cells : int
    offset_weight : ndarray, shape (Q,)
        1 where a node's element is an occluder (a gather takes the sky off its radiosity).
    """

    def __init__(self, coupling, mean, cells, offset_weight):
        self.coupling = coupling
        self.mean = mean
        self.cells = cells
        self.offset_weight = offset_weight

    def __len__(self):
        return len(self.offset_weight)

    @property
    def nbytes(self):
        return sum(a.nbytes for a in (*self.coupling, *self.mean, self.offset_weight))

    def cell_values(self, B):
        """Cell means (C, 3) of node values B (Q, 3)."""
        cell, node, weight = self.mean
        return np.stack([np.bincount(cell, weight * B[node, c], minlength=self.cells) for c in range(3)], 1)

    def solve(self, base, rho, sky, tol):
        """Node radiosities (Q, 3) by Jacobi sweeps from `base` (E + rho far light, (Q, 3)), with
        reflectances rho (Q, 3) and sky radiance (3,), until no node moves by more than tol of
        its value.

        Raises
        ------
        RuntimeError
            If MAX_SWEEPS sweeps do not get there (every node's couplings sum to at most its
            view of the scene, times rho < 1: a defect, not a slow case).
        """
        node, cell, value = self.coupling
        offset = self.offset_weight[:, None] * sky[None]
        B = base.copy()
        Q = len(B)
        for _ in range(MAX_SWEEPS):
            means = self.cell_values(B - offset)
            arriving = np.stack([np.bincount(node, value * means[cell, c], minlength=Q) for c in range(3)], 1)
            new = base + rho * arriving
            moved = np.abs(new - B)
            B = new
            if np.all(moved <= tol * np.abs(B)):
                return B
        raise RuntimeError(f"the near-field nodes did not settle in {MAX_SWEEPS} sweeps")

    @staticmethod
    def concatenate(systems):
        """Several systems side by side: (one NodeSystem, the first cell of each, (S,))."""
        nodes = np.cumsum([0] + [len(s) for s in systems[:-1]])
        cells = np.cumsum([0] + [s.cells for s in systems[:-1]])
        coupling = (
            np.concatenate([s.coupling[0] + o for s, o in zip(systems, nodes)]),
            np.concatenate([s.coupling[1] + o for s, o in zip(systems, cells)]),
            np.concatenate([s.coupling[2] for s in systems]),
        )
        mean = (
            np.concatenate([s.mean[0] + o for s, o in zip(systems, cells)]),
            np.concatenate([s.mean[1] + o for s, o in zip(systems, nodes)]),
            np.concatenate([s.mean[2] for s in systems]),
        )
        weight = np.concatenate([s.offset_weight for s in systems])
        return NodeSystem(coupling, mean, int(sum(s.cells for s in systems)), weight), cells


class NearTerms:
    """The near field of some points, kept for a relight (`gathered.GatherFactors.near`).

    Attributes
    ----------
    point, cell, value : ndarray, shape (R,)
        The points' couplings: point gets value times the cell's mean of B - offset (its near
        terms are not in its own factors).
    nodes : gathered.GatherFactors
        The nodes' far light (their own near terms left out).
    system : NodeSystem
    """

    def __init__(self, point, cell, value, nodes, system):
        order = np.argsort(point, kind="stable")  # point order (`take` searches it)
        self.point, self.cell, self.value = point[order], cell[order], value[order]
        self.nodes = nodes
        self.system = system

    @property
    def nbytes(self):
        arrays = [self.point, self.cell, self.value]
        return sum(a.nbytes for a in arrays) + self.nodes.nbytes + self.system.nbytes

    def arriving(self, base, rho, sky, tol, count):
        """What the near field adds to the points' arriving light, shape (count, 3), given the
        nodes' base (E + rho far light) and reflectances, each (Q, 3)."""
        B = self.system.solve(base, rho, sky, tol)
        means = self.system.cell_values(B - self.system.offset_weight[:, None] * sky[None])
        return np.stack(
            [np.bincount(self.point, self.value * means[self.cell, c], minlength=count) for c in range(3)], 1
        )

    def with_points(self, point, entry, scale=None):
        """The same nodes with the point couplings `entry` (E,) moved to points `point` (E,),
        their values times `scale` (E,) if given."""
        value = self.value[entry] if scale is None else self.value[entry] * scale
        return NearTerms(point, self.cell[entry], value, self.nodes, self.system)

    @staticmethod
    def concatenate(parts, offsets):
        """The near terms of several point sets, the points of part i shifted by offsets[i]
        (their node systems side by side)."""
        system, cells = NodeSystem.concatenate([p.system for p in parts])
        return NearTerms(
            np.concatenate([p.point + o for p, o in zip(parts, offsets)]),
            np.concatenate([p.cell + o for p, o in zip(parts, cells)]),
            np.concatenate([p.value for p in parts]),
            GatherFactors.concatenate([p.nodes for p in parts]),
            system,
        )


class NearField:
    """The near-field final gather of a set of points (see the module docstring).

    Parameters
    ----------
    elements : Elements
    gathered : ndarray, shape (N, 3)
        The elements' radiosities as gathers take them (`Solution`: net of the sky they hide).
    arrive : callable
        arrive(y (Q, 3), unit normals (Q, 3), element (Q,), keep) -> (arriving (Q, 3), (k, j, F V)
        triplets, direct (Q, lights)): the light arriving at points of elements, all of it (far
        and near elements at their B_j, lights, sky), as a gather gives it.
    radiosity : callable
        radiosity(element (Q,), arriving (Q, 3)) -> (E + rho arriving (Q, 3), rho (Q, 3)).
    occluding : ndarray of bool, shape (N,)
        Elements whose radiosity a gather takes the sky off.
    sky : ndarray, shape (3,)
    tol : float
    """

    def __init__(self, elements, gathered, arrive, radiosity, occluding, sky, tol):
        self.elements = elements
        self.gathered = gathered
        self.arrive = arrive
        self.radiosity = radiosity
        self.occluding = occluding
        self.sky = sky
        self.tol = tol
        self.stats = dict(near_pairs=0, near_nodes=0)

    def resolve(self, x, n, arriving, triplets, keep, factors):
        """The points' arriving light with their near elements resolved.

        Parameters
        ----------
        x, n : ndarray, shape (K, 3)
        arriving : ndarray, shape (K, 3)
            All their light as a gather gives it (near elements at their B_j).
        triplets : (k, j, F V), each shape (P,)
            Their gather factors.
        keep : bool
        factors : callable
            factors(element (Q,), triplets, direct) -> GatherFactors of node points (with `keep`).

        Returns
        -------
        arriving : ndarray, shape (K, 3)
        triplets : the factors whose terms the near field did not replace
        near : NearTerms or None (None without `keep` or with no near pair)
        """
        e = self.elements
        k, j, F = triplets
        near = near_pairs(e, x, k, j, F)
        if not near.any():
            return arriving, triplets, None
        cells = self._cells(x[k[near]], j[near])
        Q = len(cells)
        y = cells.y
        unit, _ = unit_vectors(cells.normal)
        owner = cells.element[cells.node_cell]
        node_arriving, (a, ja, Fa), direct = self.arrive(y, unit, owner, keep)
        has_cells = np.zeros(len(e), dtype=bool)
        has_cells[list(cells.roots)] = True
        node_near = near_pairs(e, y, a, ja, Fa) & has_cells[ja] & (ja != owner[a])
        coupled_nodes, node_coupling = self._couplings(cells, y, unit, a, ja, Fa, node_near)
        coupled_points, point_coupling = self._couplings(cells, x, n, k, j, F, near & has_cells[j])
        # the nodes' far light: their gather without the near terms the couplings replace
        far = node_arriving - self._constant(Q, a, ja, Fa, coupled_nodes)
        base, rho = self.radiosity(owner, far)
        weight = self.occluding[owner].astype(float)
        system = NodeSystem(node_coupling, cells.mean, len(cells.element), weight)
        terms = NearTerms(*point_coupling, None, system)
        arriving = arriving - self._constant(len(x), k, j, F, coupled_points)
        arriving = arriving + terms.arriving(base, rho, self.sky, self.tol, len(x))
        self.stats["near_pairs"] += int(coupled_points.sum())
        self.stats["near_nodes"] += Q
        kept = tuple(t[~coupled_points] for t in triplets)
        if not keep:
            return arriving, kept, None
        terms.nodes = factors(owner, tuple(t[~coupled_nodes] for t in (a, ja, Fa)), direct)
        return arriving, kept, terms

    def _constant(self, size, k, j, F, coupled):
        """sum over the coupled pairs of F V gathered_j per point, shape (size, 3)."""
        sel = np.flatnonzero(coupled)
        return np.stack(
            [np.bincount(k[sel], F[sel] * self.gathered[j[sel], c], minlength=size) for c in range(3)], 1
        )

    def _couplings(self, cells, x, n, k, j, F, near):
        """Couplings of the near pairs (k, j) to j's cells: which pairs are coupled (P,) bool and
        (rows k, cell, F V share) entries."""
        sel = np.flatnonzero(near)
        query, cell, share, has = cells.cut(x[k[sel]], n[k[sel]], j[sel])
        coupled = np.zeros(len(k), dtype=bool)
        coupled[sel[has]] = True
        return coupled, (k[sel[query]], cell, F[sel[query]] * share)

    def _cells(self, points, element):
        """Graded cells of every near element (`NodeCells`), graded toward its near points,
        then (ROUNDS) toward those and the other elements' nodes near it."""
        e = self.elements
        targets = points, element
        for _ in range(ROUNDS):
            order = np.argsort(targets[1], kind="stable")
            P, J = targets[0][order], targets[1][order]
            elements_, first = np.unique(J, return_index=True)
            bounds = np.r_[first, J.size]
            cells = NodeCells(e, [(q, P[bounds[i] : bounds[i + 1]]) for i, q in enumerate(elements_)])
            # the leaves near other elements (by boxes: which of them face each other is the
            # coupling's business) are points of the next round, by their centres
            leaf = np.flatnonzero(cells.first_child < 0)
            q, other = _box_near(e, cells.centre[leaf], cells.element[leaf])
            targets = np.concatenate([points, cells.centre[leaf[q]]]), np.concatenate([element, other])
        return cells


def _box_near(elements, y, owner):
    """(node, element) pairs with the node within NEAR_RATIO times the element's size of its
    box, the node's own element left out."""
    e = elements
    found = []
    for s in range(0, len(y), max(1, 2_000_000 // max(len(e), 1))):
        part = y[s : s + 2_000_000 // max(len(e), 1)]
        gap = lengths(np.clip(part[:, None], e.box_min[None], e.box_max[None]) - part[:, None])
        q, j = np.nonzero(gap < NEAR_RATIO * _size(e, np.arange(len(e)))[None])
        found.append((q + s, j))
    q, j = (np.concatenate(parts) for parts in zip(*found))
    keep = j != owner[q]
    q, j = q[keep], j[keep]
    # a flat element faces only nodes above its plane (coplanar neighbours exchange nothing)
    s = e.solver
    height = np.einsum("ki,ki->k", y[q] - s.plane_point[e.index[j]], s.axis[e.index[j]])
    keep = ~e.flat[j] | (height > 1e-9 * e.radius[j])
    return q[keep], j[keep]
