"""BVH scaling: time per segment query against the number of occluding triangles, 10 ... 10^6.

Two scenes, each at growing triangle counts:

- "room": a closed room (6 m cube) with two blocks standing in it, every face subdivided into
  n x n cells of two triangles (36 n^2 triangles); the segments join random points on the
  faces, as the visibility rays between patches of a radiosity scene do;
- "soup": M random triangles in the unit cube, about 1.5 / sqrt(M) across (so that a fixed share
  of random segments is blocked at every M); segments between random points of the cube.

For each count: the `core.bvh.BVH` build time, the time per query of `segments_blocked` (a
batch of QUERIES segments, median of REPEAT runs), the nodes visited and triangles tested per
query, and, up to OLD_MAX triangles, the old way on the first OLD_PAIRS / M of the segments
(10 to 200): `core.occlusion.Occluders` over the same triangles (as `Quad`s with p01 = p00),
every (segment, triangle) pair culled by the box test and the survivors tested by
`Occluders.blocked` (what `ShaftTest` + `blocked_rays` do with all occluders as candidates).
Both answers are compared. The exponent b of time per query ~ M^b is fitted over the counts
>= FIT_FROM (below that, numpy's per-call overhead dominates), and so is the slope s of time
per query ~ a + s log2 M (logarithmic growth: a constant s).

Run alone: python -m benchmarks.bvh_scaling [--quick]   (not part of the test suite)
"""

import argparse
import statistics
import time

import numpy as np

import core
from core.bvh import BVH
from core.occlusion import Occluders

ROOM_CELLS = (1, 2, 5, 17, 53, 167)  # 36, 144, 900, 10404, 101124, 1004004 triangles
SOUP_COUNTS = (10, 100, 1000, 10_000, 100_000, 1_000_000)
QUERIES = 2000
REPEAT = 3
OLD_PAIRS = 4_000_000  # (segment, triangle) pairs the old loop gets per count
OLD_QUERIES = (10, 200)  # fewest and most segments the old loop is timed on
OLD_MAX = 200_000  # the old loop (its Occluders set-up is a Python loop over surfaces) up to this count
FIT_FROM = 100
PAIR_CHUNK = 400_000  # (segment, triangle) pairs culled / tested at once by the old loop


# --------------------------------------------------------------------------- scenes
def grid_triangles(origin, du, dv, n):
    """2 n^2 triangles of the parallelogram origin + s du + t dv, s, t in [0, 1]: (2 n^2, 3, 3)."""
    s = np.arange(n + 1) / n
    P = origin + s[:, None, None] * du + s[None, :, None] * dv
    p00, p10, p11, p01 = P[:-1, :-1], P[1:, :-1], P[1:, 1:], P[:-1, 1:]
    return np.concatenate([np.stack([p00, p10, p11], -2), np.stack([p00, p11, p01], -2)]).reshape(-1, 3, 3)


def box_faces(lo, hi):
    """The 6 faces of the box [lo, hi] as (origin, du, dv)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    size = hi - lo
    faces = []
    for axis in range(3):
        u, v = (
            np.eye(3)[(axis + 1) % 3] * size[(axis + 1) % 3],
            np.eye(3)[(axis + 2) % 3] * size[(axis + 2) % 3],
        )
        for side in (lo, hi):
            origin = lo.copy()
            origin[axis] = side[axis]
            faces.append((origin, u, v))
    return faces


def room(n):
    """Room [0, 6]^3 with two blocks in it, every face n x n cells of two triangles."""
    faces = (
        box_faces((0, 0, 0), (6, 6, 6))
        + box_faces((1, 1, 0), (2.5, 3, 2.5))
        + box_faces((3.5, 3, 0), (5, 5, 4))
    )
    return np.concatenate([grid_triangles(o, du, dv, n) for o, du, dv in faces])


def soup(M, rng):
    """M random triangles in the unit cube, about 1.5 / sqrt(M) across."""
    size = min(0.3, 1.5 / np.sqrt(M))
    return rng.random((M, 1, 3)) + size * rng.standard_normal((M, 3, 3))


def room_segments(T, rng, R):
    """R segments between random points of random triangles."""
    ends = []
    for _ in range(2):
        tri = T[rng.integers(0, len(T), R)]
        w = rng.dirichlet(np.ones(3), R)
        ends.append(np.einsum("kv,kvi->ki", w, tri))
    return ends


# --------------------------------------------------------------------------- the two ways
def old_blocked(occ, p, q):
    """Every (segment, triangle) pair: box cull, then Occluders.blocked on the survivors."""
    R, M = len(p), len(occ.kind)
    blocked = np.zeros(R, dtype=bool)
    tests = 0
    rows = max(1, PAIR_CHUNK // M)
    for s in range(0, R, rows):
        k = np.arange(s, min(s + rows, R))
        lo, hi = np.minimum(p[k], q[k]), np.maximum(p[k], q[k])
        meet = np.all((occ.box_min[None] <= hi[:, None]) & (occ.box_max[None] >= lo[:, None]), axis=-1)
        seg, m = np.nonzero(meet)
        tests += seg.size
        for c in range(0, seg.size, PAIR_CHUNK):
            i, j = k[seg[c : c + PAIR_CHUNK]], m[c : c + PAIR_CHUNK]
            hit = occ.blocked(p[i], q[i], j)
            blocked[i[hit]] = True
    return blocked, tests


def median_time(function, repeat=REPEAT):
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return result, statistics.median(times)


def run_count(scene, T, p, q, log):
    M = len(T)
    start = time.perf_counter()
    bvh = BVH.from_primitives(triangles=T)
    build = time.perf_counter() - start
    eps = 1e-9 * bvh.scale
    blocked, t_new = median_time(lambda: bvh.segments_blocked(p, q, eps))
    row = dict(
        scene=scene,
        M=M,
        build_s=build,
        depth=bvh.depth,
        us_per_query=1e6 * t_new / len(p),
        nodes_per_query=bvh.stats["nodes"] / len(p),
        tests_per_query=bvh.stats["primitives"] / len(p),
        blocked=float(blocked.mean()),
        old_us_per_query=None,
        old_tests_per_query=None,
        agree=None,
    )
    R_old = int(np.clip(OLD_PAIRS // M, *OLD_QUERIES))
    if M <= OLD_MAX:
        occ = Occluders([core.Quad(a, b, c, a) for a, b, c in T])
        (old, tests), t_old = median_time(lambda: old_blocked(occ, p[:R_old], q[:R_old]), repeat=1)
        row.update(
            old_us_per_query=1e6 * t_old / R_old,
            old_tests_per_query=tests / R_old,
            agree=bool(np.array_equal(old, blocked[:R_old])),
        )
    log(
        f"  {scene:5s} M={M:>8d}  build {build:7.3f} s  {row['us_per_query']:9.1f} us/query"
        f"  nodes {row['nodes_per_query']:7.1f}  tests {row['tests_per_query']:7.1f}"
        f"  blocked {row['blocked']:.2f}"
        + (
            f"  old {row['old_us_per_query']:10.1f} us/query  agree {row['agree']}"
            if row["agree"] is not None
            else ""
        )
    )
    return row


def fit_exponent(rows, key):
    """b in key ~ M^b and s in key ~ a + s log2 M over the rows with M >= FIT_FROM (least squares)."""
    pts = [(r["M"], r[key]) for r in rows if r["M"] >= FIT_FROM and r[key]]
    if len(pts) < 2:
        return None
    M, y = np.array(pts, float).T
    return float(np.polyfit(np.log(M), np.log(y), 1)[0]), float(np.polyfit(np.log2(M), y, 1)[0])


def table(rows):
    head = (
        "| scene | triangles | depth | build (s) | BVH µs/query | nodes/query | tests/query | blocked "
        "| old µs/query | old tests/query | same answers |"
    )
    lines = [head, "|" + "---|" * 11]
    for r in rows:
        old = r["old_us_per_query"]
        lines.append(
            f"| {r['scene']} | {r['M']:,} | {r['depth']} | {r['build_s']:.3f} | {r['us_per_query']:.1f} "
            f"| {r['nodes_per_query']:.1f} | {r['tests_per_query']:.1f} | {r['blocked']:.2f} "
            f"| {'—' if old is None else f'{old:.1f}'} "
            f"| {'—' if old is None else format(r['old_tests_per_query'], '.0f')} "
            f"| {'—' if r['agree'] is None else ('yes' if r['agree'] else 'NO')} |"
        )
    return "\n".join(lines)


def measure(quick=False, log=print):
    rng = np.random.default_rng(2026)
    rows = []
    cells = ROOM_CELLS[:4] if quick else ROOM_CELLS
    counts = SOUP_COUNTS[:4] if quick else SOUP_COUNTS
    for n in cells:
        T = room(n)
        p, q = room_segments(T, rng, QUERIES)
        rows.append(run_count("room", T, p, q, log))
    for M in counts:
        T = soup(M, rng)
        p, q = rng.random((QUERIES, 3)), rng.random((QUERIES, 3))
        rows.append(run_count("soup", T, p, q, log))
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="counts up to ~10^4 only")
    args = parser.parse_args()
    rows = measure(args.quick)
    print()
    print(table(rows))
    print()
    for scene in ("room", "soup"):
        part = [r for r in rows if r["scene"] == scene]
        exponents = {
            k: fit_exponent(part, k) for k in ("us_per_query", "nodes_per_query", "old_us_per_query")
        }
        text = ", ".join(
            f"{k} ~ M^{v[0]:.2f} (or {v[1]:+.1f} per doubling)" for k, v in exponents.items() if v is not None
        )
        print(f"{scene}: fitted over M >= {FIT_FROM}: {text}")


if __name__ == "__main__":
    main()
