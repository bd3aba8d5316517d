"""Solve collected items with the core and sample the radiance at every result vertex (no bpy).

A `Session` holds one `core.Scene` built from `Collected` items. Relighting keeps the session
(and the form factors cached inside the core scene) when only reflectances, emissions, light
intensities and the sky changed: `geometry_key` fingerprints everything else. The session also
keeps the per-vertex gather's factors (`VertexGather`, with the samples' averaging onto vertices
folded in), so a relight's vertex radiance is one product after the core's re-solve instead of
a new gather.
"""

import hashlib
import time
from dataclasses import dataclass, replace

import numpy as np

from . import core


@dataclass
class Settings:
    """Solver settings.

    Attributes
    ----------
    tol : float
        Relative tolerance of `core.Scene.solve`.
    occlusion : bool
    max_bounces : int or None
        None: iterate to convergence.
    method : {"auto", "pairs", "hierarchical"}
        The core's path (`core.Scene.solve(method=)`); "auto" is resolved by `chosen_method`
        before solving.
    """

    tol: float = 1e-3
    occlusion: bool = True
    max_bounces: int = None
    method: str = "auto"


def chosen_method(method, requests):
    """The core's path for the add-on's `method`: "auto" is "hierarchical" when `requests` (the
    lightmaps and refined twins, `bake.Requests`) are not empty, "pairs" otherwise. Lightmap
    texels and refined twins show the light finer than the patches, which is right at contacts
    and seams only with the hierarchical solver's sub-patches (a floor under a resting ball:
    within 0.35 % rms of Cycles' image bake, against 1.35 % and 67 % at the contact with all
    pairs; BENCHMARKS.md); vertex colours on the user's own vertices keep the faster path."""
    if method == "auto":
        return "hierarchical" if requests else "pairs"
    return method


@dataclass
class Solution:
    """Per-target vertex radiance.

    Attributes
    ----------
    radiance : dict
        Target name -> (front, back): ndarrays of shape (N, 3) in W / (m^2 sr); back is None for
        one-sided targets.
    stats : dict
        The core's `sol.stats`.
    relit : bool
        True if the cached form factors were reused.
    core : core Solution or None
        The core's solution (for gathering at more points: lightmaps, refined twins).
    handles : list or None
        Core handle of each item of `Collected.surfaces`.
    """

    radiance: dict
    stats: dict
    relit: bool
    core: object = None
    handles: list = None


def _digest(h, value):
    """Feed a nested value (arrays, tuples, dicts, numbers, strings) into hash `h`."""
    if isinstance(value, np.ndarray):
        h.update(str((value.dtype, value.shape)).encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (tuple, list)):
        h.update(b"(")
        for v in value:
            _digest(h, v)
        h.update(b")")
    elif isinstance(value, dict):
        for k in sorted(value):
            h.update(str(k).encode())
            _digest(h, value[k])
    else:
        h.update(repr(value).encode())


def geometry_key(collected):
    """Fingerprint of everything that form factors and light visibility depend on."""
    h = hashlib.sha1()
    for item in collected.surfaces:
        s = item.surface
        if isinstance(s, core.PolygonMesh):
            _digest(h, ("PolygonMesh", s.vertices, s.loop_starts, s.loop_totals, s.corner_verts))
        else:
            geometry = {k: v for k, v in vars(s.geometry).items() if not k.startswith("_area")}
            _digest(h, (type(s).__name__, s.domain, s.orientation, geometry))
        _digest(h, (item.name, item.patches, item.occluder, item.material.two_sided))
    for light in collected.lights:
        fixed = {k: v for k, v in light.params.items() if k not in ("intensity", "irradiance")}
        _digest(h, (light.name, light.kind, fixed))
    return h.hexdigest()


class Session:
    """A core Scene built from `Collected` items, reusable for relighting: item k of
    `Collected.surfaces` is the scene's surface handle k (`skip_crossing` relies on it)."""

    def __init__(self, collected):
        self.key = geometry_key(collected)
        self.gather = None  # the VertexGather of the last full gather, for relighting
        self.scene = core.Scene()
        self.surface_handles = [_named(item.name, self._add_surface, item) for item in collected.surfaces]
        self.light_handles = [_named(light.name, self._add_light, light) for light in collected.lights]
        self.scene.set_sky(collected.sky)

    def _add_surface(self, item):
        return self.scene.add(
            item.surface,
            reflectance=item.material.reflectance,
            emission=item.material.emission,
            patches=item.patches,
            name=item.name,
            two_sided=item.material.two_sided,
            occluder=item.occluder,
        )

    def _add_light(self, light):
        add = {
            "point": self.scene.add_point_light,
            "spot": self.scene.add_spot_light,
            "sun": self.scene.add_sun_light,
        }
        return add[light.kind](name=light.name, **light.params)

    def relight(self, collected):
        """Update materials and light intensities (same geometry, see `geometry_key`)."""
        for handle, item in zip(self.surface_handles, collected.surfaces):
            self.scene.set_material(
                handle, reflectance=item.material.reflectance, emission=item.material.emission
            )
        for handle, light in zip(self.light_handles, collected.lights):
            power = {k: v for k, v in light.params.items() if k in ("intensity", "irradiance")}
            self.scene.set_light(handle, **power)
        self.scene.set_sky(collected.sky)

    def solve(self, settings, progress=None, cancel=None):
        """`core.Scene.solve`; raises core.Cancelled if `cancel()` turns True. The hierarchical
        solver also refines where the light varies beside seams and contacts
        (`light_levels`: what vertices on seams and lightmap texels show)."""
        extra = dict(light_levels=LIGHT_LEVELS) if settings.method == "hierarchical" else {}
        return self.scene.solve(
            tol=settings.tol,
            occlusion=settings.occlusion,
            max_bounces=settings.max_bounces,
            progress=progress,
            cancel=cancel,
            method=settings.method,
            **extra,
        )


LIGHT_LEVELS = 2  # the hierarchical solver's sub-patch levels where the light varies
KEEP_BYTES = 400_000_000  # kept gather factors per session (20 bytes a sparse factor, 4 a dense one)

# points per `radiosity_at` call, with progress and cancel between calls: two of the core's
# thread blocks (min_block 256), so both threads stay busy
GATHER_BLOCK = 512


class VertexGather:
    """The per-vertex gather kept for relighting, with each vertex's mean of its samples folded in.

    Built once from every sample point's factors: the samples of one vertex on one surface
    become one merged point (`core.GatherFactors.merged`, weights 1 / samples of the vertex),
    so `radiance(sol)` re-applies them to a solution of the same geometry as one product
    (`core.Solution.radiosity_from`) that gives the vertex means directly; only a vertex
    whose samples lie on several surfaces (a material border) adds up two or more of them.

    Attributes
    ----------
    factors : core.gathered.GatherFactors
        One merged point per (vertex, surface) pair, in vertex order.
    slot : ndarray of int, shape (P,)
        Each merged point's vertex in the concatenation of every target side's vertices.
    layout : list of (name, side, start, count)
        Where each target side ("front" / "back") sits in that concatenation.
    total : int
        Length of that concatenation.
    one_to_one : bool
        True if the merged points are exactly the vertices, in order (no sum needed).
    """

    def __init__(self, samples, slot, weight, layout, total):
        """
        Parameters
        ----------
        samples : core.gathered.GatherFactors
            Every sample point's factors.
        slot : ndarray of int, shape (K,)
            Each sample's vertex in the concatenation (see `layout`).
        weight : ndarray, shape (K,)
            Each sample's weight in its vertex's mean.
        layout : list of (name, side, start, count)
        total : int
        """
        span = int(samples.handle.max()) + 1 if len(samples) else 1
        pairs, group = np.unique(np.asarray(slot, np.int64) * span + samples.handle, return_inverse=True)
        self.factors = samples.merged(group.ravel(), weight, pairs.size)
        self.slot = pairs // span
        self.layout = layout
        self.total = total
        self.one_to_one = self.slot.size == total and bool(np.all(self.slot == np.arange(total)))

    def radiance(self, sol):
        """Target name -> (front (N, 3), back (N, 3) or None) from solution `sol`."""
        merged = sol.radiosity_from(self.factors)
        if self.one_to_one:
            values = merged
        else:
            values = np.stack(
                [np.bincount(self.slot, weights=merged[:, c], minlength=self.total) for c in range(3)], axis=1
            )
        return _split(values, self.layout)


def _split(values, layout):
    """Target name -> (front, back or None): the rows of `values` (total, 3) per target side."""
    out = {}
    for name, side, start, count in layout:
        front, back = out.get(name, (None, None))
        part = values[start : start + count]
        out[name] = (part, back) if side == "front" else (front, part)
    return out


def vertex_radiance(sol, handles, collected, progress=None, cancel=None, block=GATHER_BLOCK, keep=False):
    """Average each item's radiance samples onto its target's vertices.

    The gather (`Solution.radiosity_at`, threaded inside the core) runs in blocks of at most
    `block` points, each item side after side; between blocks it reports
    progress("gather", fraction of all points done) and stops if `cancel()` is true.

    Parameters
    ----------
    sol : core Solution
    handles : list
        Core handle of each item of `collected.surfaces`.
    collected : Collected
    progress : callable(stage: str, fraction: float) or None
    cancel : callable() -> bool or None
    block : int
        Points per call.
    keep : bool
        Keep the gather's factors (`Solution.gather_factors`) as a `VertexGather` and return it
        too, for relighting; the radiance is then that VertexGather's, so a relight of an
        unchanged scene gives exactly the same values.

    Returns
    -------
    dict
        Target name -> (front (N, 3), back (N, 3) or None).
    VertexGather or None
        Only with `keep` (else not returned).

    Raises
    ------
    core.Cancelled
        If `cancel()` turned true (nothing is returned).
    """
    # each target side's vertices get a range of slots in one concatenated array
    layout, offset = [], {}
    total = 0
    for name, t in collected.targets.items():
        for side in ("front", "back") if t.two_sided else ("front",):
            offset[name, side] = total
            layout.append((name, side, total, t.n_vertices))
            total += t.n_vertices
    # the work list: (handle, item, side); blocks of points within each
    work = []
    for handle, item in zip(handles, collected.surfaces):
        if item.target is None:
            continue
        work.append((handle, item, "front"))
        if collected.targets[item.target].two_sided and item.material.two_sided:
            work.append((handle, item, "back"))
    count = np.zeros(total)
    for item in collected.surfaces:  # a one-sided item's vertices count on the back too (as zeros)
        if item.target is None:
            continue
        np.add.at(count, offset[item.target, "front"] + item.vertices, 1.0)
        if collected.targets[item.target].two_sided:
            np.add.at(count, offset[item.target, "back"] + item.vertices, 1.0)
    weight = 1.0 / np.maximum(count, 1.0)
    points = sum(len(item.vertices) for _, item, _ in work)
    done = 0
    values = np.zeros((total, 3))
    parts, slots = [], []
    _report(progress, cancel, 0.0)
    for handle, item, side in work:
        for start in range(0, len(item.vertices), block):
            part = slice(start, start + block)
            u, v = item.params[part, 0], item.params[part, 1]
            if isinstance(item.surface, core.PolygonMesh):
                # a mesh's samples: face index and the position of its corner vertex
                u, v = u.astype(np.int64), item.surface.vertices[v.astype(np.int64)]
            slot = offset[item.target, side] + item.vertices[part]
            if keep:
                parts.append(sol.gather_factors(handle, u, v, side=side))
                slots.append(slot)
            else:
                np.add.at(values, slot, sol.radiosity_at(handle, u, v, side=side))
            done += len(u)
            _report(progress, cancel, done / points)
    if points == 0:
        _report(progress, cancel, 1.0)
    kept = None
    if parts:
        slot = np.concatenate(slots)
        kept = VertexGather(core.GatherFactors.concatenate(parts), slot, weight[slot], layout, total)
        out = kept.radiance(sol)
    else:
        out = _split(values * weight[:, None], layout)
    return (out, kept) if keep else out


def skip_crossing(collected, error):
    """`collected` without the objects whose surfaces `error` names (a core.CrossingSurfaceError
    from a Session of `collected`: each pass through themselves or through another, e.g. a NURBS
    net its cyclic flags fold onto itself), each with a warning in `skipped`: an object that
    cannot take part is skipped, not the whole run refused. An object's surfaces all go (its
    polygon pieces, its sides), with any lightmap or refined twin asked of it."""
    worst = {}
    for handle, total in zip(error.handles, error.row_sums):
        item = collected.surfaces[handle]
        name = item.target or item.name
        worst[name] = max(worst.get(name, 0.0), total)
    messages = [
        f"{name!r}: its surface passes through itself or through another object (a patch of it "
        f"sees {total:.3g} times a whole view, which no surface can): skipped"
        for name, total in worst.items()
    ]
    return replace(
        collected,
        surfaces=[item for item in collected.surfaces if (item.target or item.name) not in worst],
        targets={name: target for name, target in collected.targets.items() if name not in worst},
        skipped=collected.skipped + messages,
        warnings=collected.warnings + messages,
    )


def _report(progress, cancel, fraction):
    if progress is not None:
        progress("gather", fraction)
    if cancel is not None and cancel():
        raise core.Cancelled("radiosity gather cancelled")


def _named(name, function, *args):
    """function(*args), re-raising a ValueError from the core with the item's name in front."""
    try:
        return function(*args)
    except ValueError as error:
        raise ValueError(f"{name!r}: {error}") from error


_SESSIONS = {}


def solve(collected, settings, progress=None, cancel=None, relight=False, cache_key=None):
    """Build (or, for `relight`, reuse) the core scene, solve it and sample vertex radiance.

    Parameters
    ----------
    collected : Collected
    settings : Settings
    progress : callable(stage: str, fraction: float) or None
    cancel : callable() -> bool or None
    relight : bool
        Reuse the session cached under `cache_key` if its geometry is unchanged.
    cache_key : hashable or None
        Where to keep the session for later relighting (e.g. the Blender scene's name).

    Returns
    -------
    Solution
    """
    # ("auto" without outputs to bake: `pipeline.prepare` resolves it knowing them)
    settings = replace(settings, method=chosen_method(settings.method, None))
    session = _SESSIONS.get(cache_key) if relight else None
    relit = session is not None and session.key == geometry_key(collected)
    if relit:
        session.relight(collected)
    else:
        session = Session(collected)
    sol = session.solve(settings, progress, cancel)
    if cache_key is not None:
        _SESSIONS[cache_key] = session
    radiance = None
    if relit and session.gather is not None and settings.method == "pairs":  # (kept by a pairs compute)
        start = time.perf_counter()
        try:  # the kept per-vertex factors: one product
            radiance = session.gather.radiance(sol)
        except ValueError:  # (another geometry, or a black surface now lit: gather again)
            radiance = None
        sol.stats["times"]["relight_gather"] = time.perf_counter() - start
    if radiance is None:
        session.gather = None
        # kept factors hold patch radiosities; the hierarchical path gathers from its links and
        # sub-patches (`radiosity_at`), so a relight gathers again there
        keep = cache_key is not None and settings.method == "pairs"
        result = vertex_radiance(sol, session.surface_handles, collected, progress, cancel, keep=keep)
        radiance, session.gather = result if keep else (result, None)
        if session.gather is not None and session.gather.factors.nbytes > KEEP_BYTES:
            session.gather = None
    return Solution(radiance, dict(sol.stats), relit, sol, session.surface_handles)
