"""Near-field final gather: the light of nearby patches resolved across them.

A gather (`Solution.radiosity_at`) sums F(x -> j) V(x, j) B_j over the elements j, each with its
one solved radiosity B_j. Where x lies close to a large element compared with its size (the
underside of a ball hanging a few centimetres over a floor of metre-sized patches), x sees mostly
a small part of j, and the light there can be far from j's mean (the ball's own shadow on the
floor under it): the constant B_j is then wrong by up to the whole contrast of the element.

The final gather of Lischinski, Tampieri & Greenberg ("Combining hierarchical radiosity and
discontinuity meshing", SIGGRAPH 1993, section 6) answers this by gathering again at the points
of the element that x sees. Here that is done once per solution, as a small radiosity system of
its own over every element that lies near another (`NearField`):

- **near**: element i lies near element j when i's box is within NEAR_RATIO times j's size (half
  its box's diagonal) of j's box, they lie on different surfaces and can see each other, no
  closed occluding shell between them (`near_graph`); a point x is near j likewise, by its
  distance to j's box (`near_pairs`);
- **cells**: each element near another gets a quadtree of parameter cells graded toward the
  elements near it (a cell is halved while its radius exceeds GRADE times its distance from the
  nearest of their boxes, down to MAX_DEPTH halvings and MAX_CELLS cells), ORDER x ORDER Gauss
  nodes in every cell for the kernel, and one node, an unknown, at each leaf's centre
  (`graded_cells`, `NodeCells`). The cells in all are at most CELLS_PER_NEAR per near pair and
  about NODES_PER_ELEMENT nodes per element of the scene (within [MIN_NODES, MAX_NODES], their
  gathers within NODE_PAIRS (node, element) pairs: `node_budget`); each element's share of them
  is its whole graded tree's size scaled by one factor, so that a ball over one floor patch gets
  as many as a ball over four (`cell_budgets`);
- **coupling**: a point's (or node's) term F(x -> j) V(x, j) B_j becomes F V sum_c w_c Bbar_c
  over the coarsest cells c of j no larger than GRADE times their distance from x (the
  "cut", as a hierarchical radiosity link would pick them), with Bbar_c the cell's area mean of
  its nodes and w_c the point's kernel over the cell (its Gauss nodes), normalised over the
  cut: the exact F V of the pair stays, the cells only share it out (`NodeCells.cut`);
- **solve**: every node gathers the rest of the scene (far elements at their B_j, lights, sky)
  once; the nodes' radiosities then follow from B = E + rho (far + S M B), S M the couplings
  between nodes, by block Gauss-Seidel sweeps over two groups of elements from the elements' B_j
  (`NodeSystem`): light bouncing between a ball and the floor under it is resolved on both.

A gathered point's light is then its far light plus its couplings to the solved cells. All of it
depends on the solution and the point only (not on which points are gathered together).
Everything is linear in the elements' radiosities, emissions and light powers except through the
near surfaces' reflectances, so kept factors (`NearTerms`) keep the node system and a relight
solves it again (`Solution.radiosity_from`).
"""

import warnings
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext

import numpy as np

from . import ragged
from .bounds import lengths, unit_vectors
from .gathered import GatherFactors
from .transport import point_rule

NEAR_RATIO = 1.0  # a point within this times an element's size (`_size`) of its box is near
# a gathered point couples to the cells of an element with cells within this times its size (the
# kernel still varies across it there: its constant B_j left the ceiling of an open box lit from
# below 2.1 % dark about two sizes from the walls' patches, 1.0 % with the cells)
COUPLE_RATIO = 4.0
GRADE = 0.7  # a node's cell radius is at most this times its distance from the nearest near point
MAX_DEPTH = 6  # halvings of an element's parameter box toward near points
CELLS_PER_NEAR = 128  # cells (leaves and their ancestors) per element near an element, summed
MAX_CELLS = 4096  # ... at most this per element (and the size of its whole graded tree)
# nodes of a solution's near field (its cost: each node is one gathered point, a gather over all
# elements): NODES_PER_ELEMENT per element of the scene, so that it grows like the all-pairs
# solve's N^2, between MIN_NODES and MAX_NODES, and at most NODE_PAIRS / N, so that the nodes'
# gathers (and the (node, element) factors they keep for a relight) stay within NODE_PAIRS pairs
# (a 1,587-element mesh room built 65,536 nodes: 104 M pairs, 90 s and 8 GB)
NODES_PER_ELEMENT = 160
MIN_NODES = 16_384
MAX_NODES = 65_536
NODE_PAIRS = 1 << 25
NODE_CHUNK = 4096  # nodes gathered at once (bounds the temporaries of their (node, element) pairs)
START_SPLITS = 2  # cells per parameter an element starts from
ORDER = 2  # Gauss nodes per parameter in each cell
MAX_SWEEPS = 500  # sweeps of the node system
NEAR_RISE = 0.1  # a neighbour of a flat element must rise this times its size above its plane
SOLVE_FRACTION = 1e-2  # the node system is solved to this times tol of each node's value
WARM_RATIO = 100.0  # a warm start scales a node's start by at most this (`NodeSystem.warm_start`)
REFERENCES = 8  # settled solves a node system keeps, one per reflectance (`NodeSystem.solve`)


def near_pairs(elements, x, k, j, F, ratio=None):
    """Which (point, element) pairs of a gather are near, shape (P,) bool: F > 0 and the point
    x_k within `ratio` (default NEAR_RATIO) times element j's size (half its box's diagonal) of
    its box."""
    e = elements
    # (np.take: a row gather of an (N, 3) table costs four times as much by fancy indexing)
    point, low, high = np.take(x, k, axis=0), np.take(e.box_min, j, axis=0), np.take(e.box_max, j, axis=0)
    gap = lengths(np.clip(point, low, high) - point)
    ratio = NEAR_RATIO if ratio is None else ratio
    return (F > 0.0) & (gap < ratio * _half_diagonal(low, high))


def _size(elements, j):
    """Half the diagonal of elements' boxes, shape (K,): their size for `near_pairs` (a bounding
    radius can be far larger: a whole sphere's)."""
    return _half_diagonal(elements.box_min[j], elements.box_max[j])


def _half_diagonal(low, high):
    return 0.5 * lengths(high - low)


def graded_cells(elements, element, near, budget):
    """A quadtree of parameter cells on `element` graded toward `near` (see the module
    docstring): every cell made, leaves and their ancestors.

    Parameters
    ----------
    elements : Elements
    element : int
    near : ndarray, shape (B, 2, 3)
        Boxes (min, max corners) of the elements near this one.
    budget : int
        Cells it may make (the nearest are split first).

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
        gap = np.maximum(_nearest(centre, near) - radius, 0.0)
        split = radius > GRADE * gap
        room = budget - total
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


def cell_budgets(elements, targets):
    """Cells each near element may make, shape (T,): its whole graded tree's size (`graded_cells`
    within MAX_CELLS), all scaled by one factor to a total of what shares of CELLS_PER_NEAR per
    element near it (MAX_CELLS at most) would make, scaled to the solution's node budget
    (`node_budget`: NODES_PER_ELEMENT per element of the scene, within [MIN_NODES, MAX_NODES]
    and NODE_PAIRS / N; a leaf is a node, about 3/4 of cells), each no larger than its whole
    tree. (Handing the cells that
    per-pair shares leave unused to others instead filled the cap: the Cornell box's seams all
    want full trees, 65,586 nodes and 41 s against 47,283 and 33 s.)

    An element's share then follows how much of it lies near others: a ball over one floor
    patch gets as many cells as a ball over four (shares by the number of neighbours gave it a
    quarter: 3.7 % rms off Cycles on example 05 against 2.3 %, at the same nodes and time).

    Parameters
    ----------
    targets : list of (element, boxes (B, 2, 3) of the B elements near it)
    """
    neighbours = np.array([len(near) for _, near in targets])
    whole = np.array([len(graded_cells(elements, q, near, MAX_CELLS)[0]) for q, near in targets])
    nodes = node_budget(len(elements))
    share = np.minimum(CELLS_PER_NEAR * neighbours, MAX_CELLS)
    total = np.minimum(share * min(1.0, nodes / (0.75 * share.sum())), whole).sum()
    return np.maximum(np.floor(whole * min(1.0, total / whole.sum())), 8).astype(int)


def node_budget(n_elements):
    """Nodes a near field of a scene of `n_elements` elements may build (see NODE_PAIRS)."""
    nodes = np.clip(NODES_PER_ELEMENT * n_elements, MIN_NODES, MAX_NODES)
    return int(max(min(nodes, NODE_PAIRS // max(n_elements, 1)), 1))


def _nearest(centre, boxes):
    """Distance from each centre (C, 3) to the nearest of `boxes` (B, 2, 3), shape (C,)."""
    block = max(1, 2_000_000 // max(len(centre), 1))
    gap = np.full(len(centre), np.inf)
    for start in range(0, len(boxes), block):  # (centres x boxes, in blocks)
        lo, hi = boxes[None, start : start + block, 0], boxes[None, start : start + block, 1]
        d = np.maximum(0.0, np.maximum(lo - centre[:, None], centre[:, None] - hi))
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
    first_root : ndarray of int, shape (N,)
        Each element's first root cell (its START_SPLITS^2 roots are consecutive), -1 if none.
    node_cell : ndarray of int, shape (Q,)
        The leaf of each node.
    y, normal, area : ndarray, shape (Q, 3), (Q, 3), (Q,)
        Nodes, unnormalised front normals and their leaves' areas.
    mean : (cell, node, weight)
        Each cell's area mean over the nodes of its leaves, as sparse entries.
    """

    def __init__(self, elements, targets, budgets):
        e = elements
        parts, offset = [], 0
        self.first_root = np.full(len(e), -1)
        for (q, near), budget in zip(targets, budgets):
            boxes, parent, first = graded_cells(e, q, near, budget)
            parent = np.where(parent >= 0, parent + offset, -1)
            parts.append((np.full(len(boxes), q), boxes, parent, np.where(first >= 0, first + offset, -1)))
            self.first_root[q] = offset
            offset += len(boxes)
        self.element, boxes, self.parent, self.first_child = (np.concatenate(p) for p in zip(*parts))
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
        cell = (self.first_root[element][:, None] + np.arange(R)).ravel()
        found_q, found_c = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
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
    """The nodes' radiosities: B = base + rho (S M (B - offset)), with M the cells' area means of
    the nodes (`NodeCells.mean`) and S each node's couplings to cells.

    Solved by block Gauss-Seidel sweeps over two groups of elements (`_two_groups`): a node
    couples only to other elements' cells, mostly across a contact (a ball and the floor under
    it), so light bounces between the groups and a sweep that updates one group from the
    other's new values does the work of two Jacobi sweeps (the Cornell box's 47,334 nodes: 33
    sweeps instead of 65 to the same bound), over-relaxed as that two-group structure allows
    (`overrelaxation`).

    Parameters
    ----------
    coupling : (node, cell, value), each shape (Z,)
        S: node gets value times the mean of the cell.
    mean : (cell, node, weight)
        M.
    cells : int
    node_element : ndarray of int, shape (Q,)
        Each node's element (a solve starts from the elements' radiosities).
    offset_weight : ndarray, shape (Q,)
        1 where a node's element is an occluder (a gather takes the sky off its radiosity).
    nodes : gathered.GatherFactors or None
        The nodes' far light (their near terms left out), for a relight.
    """

    def __init__(self, coupling, mean, cells, node_element, offset_weight, nodes=None):
        self.coupling = coupling
        self.mean = mean
        self.cells = cells
        self.node_element = node_element
        self.offset_weight = offset_weight
        self.nodes = nodes
        # per reflectance (its bytes): the first settled solve's inputs and answer, at most
        # REFERENCES of them (`solve`, `warm_start`); and the key of the latest
        self.references, self.latest = {}, None
        self.sweeps = np.zeros(3, dtype=np.int64)  # the latest solve's sweeps, channel by channel
        node, cell, value = coupling
        self.row_sum = np.bincount(node, value, minlength=len(node_element))
        # per group: its nodes, and its couplings with their nodes' positions within the group
        cell_element = np.zeros(cells, dtype=np.int64)
        cell_element[mean[0]] = node_element[mean[1]]
        elements = int(node_element.max(initial=-1)) + 1
        group = _two_groups(node_element[node], cell_element[cell], elements)
        # the means' entries sorted by cell, as runs (`cell_values`)
        order = np.argsort(mean[0], kind="stable")
        self._mean_runs = (*_runs(mean[0][order]), mean[1][order], mean[2][order])
        # per group: (its nodes, its couplings sorted by node as runs: where each run starts
        # and its node's position in the group, each run's cells and values: `_sum_runs`; the
        # means' runs of the cells those couplings read)
        self.groups = []
        for g in (0, 1):
            members = np.flatnonzero(group[node_element] == g)
            position = np.full(len(node_element), -1)
            position[members] = np.arange(members.size)
            entry = np.flatnonzero(group[node_element[node]] == g)
            entry = entry[np.argsort(node[entry], kind="stable")]
            read = np.zeros(cells, dtype=bool)
            read[cell[entry]] = True
            runs = (*_runs(position[node[entry]]), cell[entry], value[entry])
            self.groups.append((members, runs, _runs_of(self._mean_runs, read)))
        self._parts = {}  # threads -> the runs cut for them (`_split`)

    def __len__(self):
        return len(self.node_element)

    @property
    def nbytes(self):
        arrays = (*self.coupling, *self.mean, self.node_element, self.offset_weight, self.row_sum)
        arrays += (*self._mean_runs, *(a for m, runs, means in self.groups for a in (m, *runs, *means)))
        return sum(a.nbytes for a in arrays) + (self.nodes.nbytes if self.nodes is not None else 0)

    def cell_values(self, B):
        """Cell means (C, 3) of node values B (Q, 3)."""
        return _sum_runs([self._mean_runs], self.cells, B.T.copy()).T

    def _split(self, threads):
        """Each group's (members, runs, its cells' means' runs), the runs cut into `threads`
        parts each (`_split_runs`)."""
        if threads not in self._parts:
            self._parts[threads] = [
                (members, _split_runs(runs, threads), _split_runs(means, threads))
                for members, runs, means in self.groups
            ]
        return self._parts[threads]

    def solve(self, base, rho, sky, tol, start, threads=1):
        """Node radiosities (Q, 3) from `base` (E + rho far light, (Q, 3)), reflectances rho
        (Q, 3), sky radiance (3,) and a first guess `start` (Q, 3), by block Gauss-Seidel
        sweeps: each group's nodes from the latest values of all cells.

        With K = rho S M (non-negative, row sums at most q = max over nodes of rho times the
        node's couplings, its near view; each channel a system of its own), each updated value
        is a non-negative mix of values whose errors are at most the sweep's starting error,
        with weights adding up to at most q: a sweep contracts the error in the max norm by at
        most q, as a Jacobi sweep does (and is a regular splitting of I - K that converges no
        slower: Varga, "Matrix Iterative Analysis", 1962, section 3.6), so the error after a
        sweep is at most q / (1 - q) times the sweep's largest change. Sweeps stop once
        q / (1 - q) times each node's own change is within SOLVE_FRACTION * tol of its value: that
        per-node reading is what the sweeps give once one slow mode dominates (each node's error
        and change then shrink together), not a proof (dark nodes deep in a contact would
        otherwise be held to the brightest node's change); measured against many more sweeps, 4x
        inside it on a ball resting on a floor (11,721 nodes) and against a dense solve in
        tests/test_nearfield.py. Past MAX_SWEEPS a warning says how far it got.

        The first sweep is plain; the ones after it over-relax each update by `overrelaxation`'s
        factor w (new = old + w (Gauss-Seidel value - old)). An over-relaxed sweep is no
        contraction in the max norm, so its change bounds nothing: once it is within the stop
        rule, one plain sweep follows, and only a plain sweep's change can stop the solve (the
        bound above then holds as it stands). If three over-relaxed sweeps do not shrink the
        change, the rest are plain. The slow part of the solve is light bouncing in the wedge
        where a ball meets the floor, each round trip losing rho_ball rho_floor: plain sweeps
        take 41-44 to the bound there (a 10,118-vertex ball on a floor), over-relaxed 19-20.

        Every solve after the first starts from `start` times what an earlier solve made of its
        own start, node by node (`warm_start`): the first one with the same reflectances if
        there was one, else the latest. After a light's power changed that is the answer and
        one sweep confirms it (the ball on a floor: 1 sweep instead of 44); after a small change
        of colour, a start near it. A solve whose inputs (start, base, sky, tol) equal that first
        one's returns its answer. So the answer depends, within the bound (measured 3e-10 of the
        brightest node), on the first solve with these reflectances (and that one on the solve
        before it) and on nothing else: the same solution solved again gives the same answer to
        the last bit. At most REFERENCES reflectances are kept (the oldest dropped first).

        A group's update is a Jacobi step within the group (each node from the other group's
        cells), so `threads` threads share its runs of couplings with the same answer to the
        last bit (numpy releases the GIL in the gathers and sums)."""
        key = rho.tobytes()
        known = self.references.get(key)
        if known is not None and all(
            np.array_equal(a, b) for a, b in zip(known[:4], (start, base, sky, tol))
        ):
            self.sweeps = np.zeros(3, dtype=np.int64)
            return known[4].copy()
        with ThreadPoolExecutor(threads) if threads > 1 else nullcontext() as pool:
            return self._sweep(base, rho, sky, tol, start, key, (pool, threads))

    def _sweep(self, base, rho, sky, tol, start, key, workers):
        """`solve`'s sweeps, in workers (pool or None, threads), channel by channel: arrays
        (3, Q) and (3, C) (`_sum_runs`). The channels are three systems of their own, each
        with its own contraction q, over-relaxation, plain sweeps and stop; a channel that has
        stopped is swept no more (a relight that changes one channel's colour sweeps the other
        two once; `key`: the reflectances' bytes, `_keep`)."""
        inputs = (start.copy(), base.copy(), sky.copy(), tol)
        pool, threads = workers
        offset = sky[:, None] * self.offset_weight[None]
        q = np.max(rho * self.row_sum[:, None], axis=0, initial=0.0)  # (3,)
        factor = q / np.maximum(1.0 - q, SOLVE_FRACTION)  # (q < 1: `_within_view`, rho < 1)
        omega = self.overrelaxation(rho)
        B, base, rho = self.warm_start(start, key).T.copy(), base.T.copy(), rho.T.copy()
        plain, active = np.ones(3, dtype=bool), np.ones(3, dtype=bool)
        changes, bound = [[], [], []], np.zeros_like(B)
        self.sweeps = np.zeros(3, dtype=np.int64)
        for _ in range(MAX_SWEEPS):
            c = np.flatnonzero(active)
            self.sweeps[c] += 1
            last = B[c]
            w = omega[c, None]
            for members, runs, means in self._split(threads):
                if members.size:
                    cell_means = _sum_runs(means, self.cells, B[c] - offset[c], pool)  # (channels, C)
                    arriving = _sum_runs(runs, members.size, cell_means, pool)
                    now = B[c][:, members]
                    update = base[c][:, members] + rho[c][:, members] * arriving
                    B[c[:, None], members] = np.where(plain[c, None], update, now + w * (update - now))
            change = np.abs(B[c] - last)
            bound[c] = factor[c, None] * change
            within = np.all(bound[c] <= SOLVE_FRACTION * tol * np.abs(B[c]), axis=1)
            active[c[within & plain[c]]] = False
            if not active.any():
                self._keep(key, inputs, B.T.copy())
                return B.T.copy()
            for row, k in enumerate(c):
                changes[k].append(float(change[row].max(initial=0.0)))
                if len(changes[k]) > 3 and changes[k][-1] >= changes[k][-4]:
                    omega[k] = 1.0  # not settling over-relaxed: plain sweeps from here on
            plain[c] = within | (omega[c] == 1.0)
        worst = float(np.max(bound / np.maximum(np.abs(B), 1e-300)))
        warnings.warn(
            f"the near-field nodes did not settle in {MAX_SWEEPS} sweeps (error bound {worst:.1e} of "
            f"their values, contraction {q.max():.4f})",
            RuntimeWarning,
            stacklevel=3,
        )
        return B.T.copy()

    def overrelaxation(self, rho):
        """The over-relaxation factor per channel, shape (3,), for reflectances rho (Q, 3).

        With the couplings only between the two groups, the Jacobi iteration matrix is 2-cyclic
        and its spectral radius mu has mu^2 = rho(K_ab K_ba) <= q_a q_b, with q_g the largest row
        sum of K within group g. For such a (consistently ordered) matrix, Young's theory gives
        the best factor 2 / (1 + sqrt(1 - mu^2)) and a convergence rate of w - 1 per sweep
        against mu^2 for plain Gauss-Seidel (Young, "Iterative methods for solving partial
        difference equations of elliptic type", Trans. AMS 76, 1954; Varga 1962, chapter 4);
        taken here with mu^2 = q_a q_b. That is a bound, not an estimate: where it overshoots
        mu^2 the factor is a little larger than best, which costs less than one smaller than
        best would (the rate falls steeply in w up to the best factor and rises as w - 1 past
        it, ibid.). Couplings within a group (odd cycles) leave the matrix not quite 2-cyclic;
        the stop rule relies on none of this (`solve`)."""
        rows = [
            np.zeros(3) if members.size == 0 else (rho[members] * self.row_sum[members, None]).max(0)
            for members, *_ in self.groups
        ]
        mu2 = np.clip(rows[0] * rows[1], 0.0, 1.0)
        return 2.0 / (1.0 + np.sqrt(1.0 - mu2))

    def _keep(self, key, inputs, answer):
        """Keep a settled solve's inputs and answer as its reflectances' first (`solve`)."""
        if key not in self.references:
            if len(self.references) >= REFERENCES:
                del self.references[next(iter(self.references))]  # (the oldest)
            self.references[key] = (*inputs, answer)
        self.latest = key

    def warm_start(self, start, key=None):
        """A first guess (Q, 3) from `start` (Q, 3): start itself for the first solve, after it
        start times a kept answer's ratio to its own start per node and channel (1 where that
        start was dark, at most WARM_RATIO): the first settled solve's with reflectances `key`
        (their bytes) if kept, else the latest settled solve's."""
        reference = self.references.get(key, self.references.get(self.latest))
        if reference is None:
            return start.copy()
        first_start, first = reference[0], reference[4]
        lit = first_start > 1e-12 * max(float(np.abs(first_start).max(initial=0.0)), 1e-300)
        ratio = np.divide(first, first_start, out=np.ones_like(first), where=lit)
        return start * np.clip(ratio, 0.0, WARM_RATIO)

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
        joined = NodeSystem(
            coupling,
            mean,
            int(sum(s.cells for s in systems)),
            np.concatenate([s.node_element for s in systems]),
            np.concatenate([s.offset_weight for s in systems]),
            GatherFactors.concatenate([s.nodes for s in systems]),
        )
        return joined, cells


class NearTerms:
    """The near field of some points, kept for a relight (`gathered.GatherFactors.near`).

    Attributes
    ----------
    point, cell, value : ndarray, shape (R,)
        The points' couplings: point gets value times the cell's mean of B - offset (their near
        terms are not in the points' own factors).
    system : NodeSystem
        With its `nodes` factors.
    """

    def __init__(self, point, cell, value, system):
        order = np.argsort(point, kind="stable")  # point order (`take` searches it)
        self.point, self.cell, self.value = point[order], cell[order], value[order]
        self.system = system
        self._point_runs = None  # (`arriving`, on first use)

    @property
    def nbytes(self):
        return sum(a.nbytes for a in (self.point, self.cell, self.value)) + self.system.nbytes

    def arriving(self, base, rho, sky, tol, start, count, threads=1):
        """What the near field adds to the points' arriving light, shape (count, 3), given the
        nodes' base (E + rho far light), reflectances and first guess, each (Q, 3), the nodes
        solved in `threads` threads."""
        system = self.system
        B = system.solve(base, rho, sky, tol, start, threads)
        means = system.cell_values(B - system.offset_weight[:, None] * sky[None])
        if self._point_runs is None:  # (points sorted: `__init__`)
            self._point_runs = (*_runs(self.point), self.cell, self.value)
        return _sum_runs([self._point_runs], count, means.T.copy()).T

    def with_points(self, point, entry, scale=None):
        """The same nodes with the point couplings `entry` (E,) moved to points `point` (E,),
        their values times `scale` (E,) if given."""
        value = self.value[entry] if scale is None else self.value[entry] * scale
        return NearTerms(point, self.cell[entry], value, self.system)

    @staticmethod
    def concatenate(parts, offsets):
        """The near terms of several point sets, the points of part i shifted by offsets[i] (one
        node system if they share it, else their systems side by side)."""
        if all(p.system is parts[0].system for p in parts):
            system, cells = parts[0].system, np.zeros(len(parts), dtype=np.int64)
        else:
            system, cells = NodeSystem.concatenate([p.system for p in parts])
        return NearTerms(
            np.concatenate([p.point + o for p, o in zip(parts, offsets)]),
            np.concatenate([p.cell + o for p, o in zip(parts, cells)]),
            np.concatenate([p.value for p in parts]),
            system,
        )


class NearField:
    """The near-field final gather of one solution (see the module docstring): node cells on
    every element that lies near another, solved once; points gathered later couple to them.

    Parameters
    ----------
    elements : Elements
    B, gathered : ndarray, shape (N, 3)
        The elements' radiosities, and as gathers take them (net of the sky they hide).
    arrive : callable
        arrive(y (Q, 3), unit normals (Q, 3), element (Q,)) -> (arriving (Q, 3), (k, j, F V)
        triplets, direct (Q, lights)): all the light arriving at points of elements (far and
        near elements at their B_j, lights, sky) as a kept gather gives it.
    radiosity : callable
        radiosity(element (Q,), arriving (Q, 3)) -> (E + rho arriving (Q, 3), rho (Q, 3)).
    factors : callable
        factors(element (Q,), triplets, direct) -> GatherFactors of points of those elements.
    occluding : ndarray of bool, shape (N,)
        Elements whose radiosity a gather takes the sky off.
    sky : ndarray, shape (3,)
    tol : float
    threads : int
        Threads of the nodes' solve (`NodeSystem.solve`).
    """

    def __init__(self, elements, B, gathered, arrive, radiosity, factors, occluding, sky, tol, threads=1):
        e = elements
        self.elements = e
        self.gathered = gathered
        self.stats = dict(near_elements=0, near_nodes=0, near_pairs=0)
        self.cells = None
        self.has_cells = np.zeros(len(e), dtype=bool)
        i, j = near_graph(e, occluding)
        if i.size == 0:
            return
        # each element's cells graded toward the boxes of the elements near it
        boxes = np.stack([e.box_min, e.box_max], 1)
        order = np.argsort(j, kind="stable")
        i, j = i[order], j[order]
        owners, first = np.unique(j, return_index=True)
        bounds = np.r_[first, j.size]
        targets = [(q, boxes[i[bounds[c] : bounds[c + 1]]]) for c, q in enumerate(owners)]
        self.cells = cells = NodeCells(e, targets, cell_budgets(e, targets))
        self.has_cells = cells.first_root >= 0
        # the nodes' own gathers, their near terms replaced by couplings to the cells
        unit, _ = unit_vectors(cells.normal)
        owner = cells.element[cells.node_cell]
        far, coupling, kept, direct = self._node_gathers(cells.y, unit, owner, arrive)
        base, rho = radiosity(owner, far)
        nodes = factors(owner, kept, direct)
        weight = occluding[owner].astype(float)
        self.system = NodeSystem(coupling, cells.mean, len(cells.element), owner, weight, nodes)
        node_B = self.system.solve(base, rho, sky, tol, B[owner], threads)
        self.means = self.system.cell_values(node_B - weight[:, None] * sky[None])
        self.stats.update(near_elements=int(owners.size), near_nodes=len(cells))

    def _node_gathers(self, y, unit, owner, arrive):
        """The nodes' gathers, NODE_CHUNK nodes at a time (each node's terms are its own).

        Returns
        -------
        far : ndarray, shape (Q, 3)
            Light arriving at each node from all but its coupled pairs.
        coupling : (node, cell, value)
            Couplings of the near pairs to their elements' cells (`NodeSystem`).
        kept : (node, element, F V)
            The factors of the pairs not coupled (the far light, for a relight).
        direct : ndarray, shape (Q, lights)
        """
        e = self.elements
        far = np.zeros((len(y), 3))
        couplings, kept, direct = [], [], []
        for start in range(0, len(y), NODE_CHUNK):
            rows = slice(start, start + NODE_CHUNK)
            x, n, home = y[rows], unit[rows], owner[rows]
            arriving, (a, ja, Fa), lit = arrive(x, n, home)
            near = near_pairs(e, x, a, ja, Fa) & self.has_cells[ja] & (ja != home[a])
            coupled, coupling = self._couplings(x, n, a, ja, Fa, near)
            node, cell, value = _within_view(coupling, a, Fa, coupled, len(x))
            couplings.append((node + start, cell, value))
            far[rows] = arriving - self._constant(len(x), a, ja, Fa, coupled)
            kept.append((a[~coupled] + start, ja[~coupled], Fa[~coupled]))
            direct.append(lit)
        join = lambda parts: tuple(np.concatenate(t) for t in zip(*parts))  # noqa: E731
        return far, join(couplings), join(kept), np.concatenate(direct)

    def resolve(self, x, n, arriving, triplets, reach, keep):
        """The points' arriving light with their near elements resolved.

        Parameters
        ----------
        x, n : ndarray, shape (K, 3)
        arriving : ndarray, shape (K, 3)
            All their light as a gather gives it (near elements at their B_j).
        triplets : (k, j, F V), each shape (P,)
            Their gather factors.
        reach : ndarray of bool, shape (P,)
            The pairs within COUPLE_RATIO of their element (`near_pairs`): those with cells
            are coupled to them.
        keep : bool

        Returns
        -------
        arriving : ndarray, shape (K, 3)
        triplets : the factors whose terms the near field did not replace
        near : NearTerms or None (None without `keep` or with no near pair)
        """
        if self.cells is None:
            return arriving, triplets, None
        k, j, F = triplets
        near = reach & self.has_cells[j]
        if not near.any():
            return arriving, triplets, None
        coupled, (point, cell, value) = self._couplings(x, n, k, j, F, near)
        arriving = arriving - self._constant(len(x), k, j, F, coupled)
        for c in range(3):
            arriving[:, c] += np.bincount(point, value * self.means[cell, c], minlength=len(x))
        self.stats["near_pairs"] += int(coupled.sum())
        kept = tuple(t[~coupled] for t in triplets)
        return arriving, kept, (NearTerms(point, cell, value, self.system) if keep else None)

    def _constant(self, size, k, j, F, coupled):
        """sum over the coupled pairs of F V gathered_j per point, shape (size, 3)."""
        sel = np.flatnonzero(coupled)
        return np.stack(
            [np.bincount(k[sel], F[sel] * self.gathered[j[sel], c], minlength=size) for c in range(3)], 1
        )

    def _couplings(self, x, n, k, j, F, near):
        """Couplings of the near pairs (k, j) to j's cells: which pairs are coupled (P,) bool and
        (rows k, cell, F V share) entries."""
        sel = np.flatnonzero(near)
        query, cell, share, has = self.cells.cut(x[k[sel]], n[k[sel]], j[sel])
        coupled = np.zeros(len(k), dtype=bool)
        coupled[sel[has]] = True
        return coupled, (k[sel[query]], cell, F[sel[query]] * share)


def _runs(keys):
    """(where each run of equal keys starts, each run's key), shapes (R,), of sorted keys (Z,)."""
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]]) if keys.size else keys
    return starts, keys[starts]


def _split_runs(runs, parts):
    """Runs (starts, keys, index, weight) of sorted entries cut at run boundaries into at most
    `parts` runs of about equal entries, a list (`_sum_runs` takes them in threads)."""
    starts, keys, index, weight = runs
    if parts <= 1 or starts.size < 2 * parts:
        return [runs]
    cuts = np.searchsorted(starts, np.linspace(0, index.size, parts + 1)[1:-1])
    bounds = np.unique(np.r_[0, cuts, starts.size])
    ends = np.r_[starts, index.size]
    return [
        (starts[lo:hi] - ends[lo], keys[lo:hi], index[ends[lo] : ends[hi]], weight[ends[lo] : ends[hi]])
        for lo, hi in zip(bounds[:-1], bounds[1:])
    ]


def _runs_of(runs, keep):
    """The runs (starts, keys, index, weight) whose key has keep[key] (keep: bool array)."""
    starts, keys, index, weight = runs
    pick = np.flatnonzero(keep[keys])
    length = np.diff(np.r_[starts, index.size])[pick]
    _, entry = ragged.expand(starts[pick], length)
    return ragged.starts(length), keys[pick], index[entry], weight[entry]


def _sum_runs(parts, count, channels, pool=None):
    """Sums (channels, count) over runs (starts, keys, index, weight) of sorted entries: row keys[r] of
    channel c gets the sum of weight * channels[c, index] over run r (np.add.reduceat, 5-7x
    faster than np.bincount over the same entries). channels: (channels, M), C-contiguous; parts: a
    list of such runs with no key in two (`_split_runs`), summed in `pool`'s threads if given.
    Rows that no run names are 0."""
    out = np.zeros((len(channels), count))

    def add(runs):
        starts, keys, index, weight = runs
        for c in range(len(channels) if starts.size else 0):
            out[c, keys] = np.add.reduceat(weight * channels[c][index], starts)

    if pool is None or len(parts) == 1:
        for runs in parts:
            add(runs)
    else:
        list(pool.map(add, parts))
    return out


def _two_groups(receiver, sender, count):
    """Elements in two groups, shape (count,) of 0 or 1, such that couplings (receiver element,
    sender element), each shape (Z,), mostly join elements of different groups: each connected
    part of the coupling graph coloured alternately outward from its first element (a graph
    with odd cycles keeps some couplings within a group: those take their values from before
    the group's update)."""
    group = np.full(count, -1)
    joined = np.unique(receiver * max(count, 1) + sender)
    pairs = np.stack([joined // max(count, 1), joined % max(count, 1)], 1)
    pairs = np.concatenate([pairs, pairs[:, ::-1]])
    pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
    first = np.searchsorted(pairs[:, 0], np.arange(count + 1))
    for root in np.unique(receiver):
        if group[root] >= 0:
            continue
        group[root] = 0
        frontier = [root]
        while frontier:
            element = frontier.pop()
            for other in pairs[first[element] : first[element + 1], 1]:
                if group[other] < 0:
                    group[other] = 1 - group[element]
                    frontier.append(other)
    return np.maximum(group, 0)


def _within_view(coupling, a, F, coupled, count):
    """Couplings scaled so that no node's factors add up past 1 (a node where two surfaces
    touch can get point factors that overshoot a little: the node system would then not
    contract)."""
    node, cell, value = coupling
    far = np.bincount(a[~coupled], F[~coupled], minlength=count)
    near = np.bincount(node, value, minlength=count)
    room = np.clip(1.0 - far, 0.0, None)
    scale = np.where(near > room, room / np.maximum(near, 1e-300), 1.0)
    return node, cell, value * scale[node]


def near_graph(elements, occluding):
    """Element pairs (i, j), shapes (P,), with i's box within NEAR_RATIO times j's size of j's
    box, on different surfaces (the patches of one surface are not resolved against each other:
    a NURBS or a tube's inside stays piecewise constant), that can exchange light (`Elements.live`,
    no closed shell of the `occluding` elements (N,) between them: a ball's inside is not near the
    floor under it), and a flat j facing i's box (its highest corner NEAR_RISE of i's size above
    j's plane)."""
    e = elements
    N = len(e)
    size = _size(e, np.arange(N))
    found = []
    block = max(1, 4_000_000 // max(N, 1))
    for s in range(0, N, block):
        lo, hi = e.box_min[s : s + block, None], e.box_max[s : s + block, None]
        gap = lengths(np.maximum(0.0, np.maximum(lo - e.box_max[None], e.box_min[None] - hi)))
        a, b = np.nonzero(gap < NEAR_RATIO * size[None])
        found.append((a + s, b))
    i, j = (np.concatenate(parts) for parts in zip(*found))
    keep = e.geometry[i] != e.geometry[j]
    i, j = i[keep], j[keep]
    keep = e.live(i, j) & ~e.sealed_between(i, j, occluding)
    i, j = i[keep], j[keep]
    # a flat j sees only what lies above its plane: the highest corner of i's box, which must
    # rise by NEAR_RISE of i's size (a neighbour a few degrees off j's plane sends it ~nothing)
    solver = e.solver
    axis = solver.axis[e.index[j]]
    point = solver.plane_point[e.index[j]]
    top = np.where(axis > 0, e.box_max[i], e.box_min[i])
    above = np.einsum("ki,ki->k", top - point, axis) > NEAR_RISE * size[i]
    keep = ~e.flat[j] | above
    return i[keep], j[keep]
