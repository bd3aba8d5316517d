"""Radiosity scenes of curved and flat patches: their inputs and how a solve runs (the cached pair
data is `paircache.PairCache`'s; the result, `solution.Solution`, holds per-patch and per-point
results).

    scene = Scene()
    h = scene.add(Sphere((0, 0, 1), 0.5), reflectance=0.7, patches=(6, 8))
    scene.add(Quad(...), emission=(10, 10, 10))
    sol = scene.solve(tol=1e-3)
    sol.radiosity(h)              # per patch, (nu * nv, 3), patch i * nv + j = cell (i, j)
    sol.radiosity_at(h, u, v)     # at parameter points, gathered from every patch
    m = scene.add(PolygonMesh(vertices, faces))   # a mesh: patches per face piece
    sol.radiosity(m); sol.vertex_radiosity(m)     # per face, per vertex

Per channel B_i = E_i + rho_i sum_j F_ij B_j (+ rho_i / pi times direct irradiance from point,
spot and sun lights, + rho_i L (1 - sum_j F_ij) for a uniform sky of radiance L, `set_sky`, the
sum over the occluders' elements: the part of i's hemisphere that no surface covers). B and E
may be radiances (W m^-2 sr^-1) or exitances: the equation is the same. F includes occlusion
by every surface added with occluder=True. On the all-pairs path a flat patch that another
object's face lies on (a floor under a box resting there) has B_i the mean over its free part:
its gathered light is divided by its free fraction (`coverage`).

Work that a solve skips, each counted in `Solution.stats`: pairs that cannot face each other
(bounds), occlusion rays for pairs whose shaft holds no occluder, rows of black non-emitting
patches and columns that carry no light. Form factors and visibilities are cached by geometry:
`set_material` and `set_light` followed by `solve` reuse them.
"""

import sys

import numpy as np

from . import checks, solvers
from .elements import piece_patches
from .hclosure import BACK_HALF, FRONT_HALF, ONE_SIDED
from .hierarchical import HierarchicalRadiosity
from .lights import PointLight, SpotLight, SunLight
from .mesh import PolygonMesh
from .paircache import PairCache, ordered_pairs
from .runner import Run
from .solution import Solution
from .surface import Surface

AUTO_PATCH_SIZE = 0.1  # automatic patches: about this fraction of the scene's size at tol 1e-3
MAX_AUTO_PATCHES = 32
MAX_ELEMENTS = 20_000  # patches a solve accepts (~90 bytes per pair that faces: up to ~18 GB)
MAX_HIERARCHICAL_ELEMENTS = 200_000  # patches a hierarchical solve accepts
MAX_CONTACT_LEVELS = 6  # sub-patch levels a hierarchical solve accepts, each kind (4^6 a patch)
LINEAR_SOLVERS = (None, "direct", "iterative", "gmres", "jacobi")
PATHS = ("pairs", "hierarchical")


def _path_and_solver(method):
    """(transport path, linear solver) from `solve`'s method argument."""
    if method in PATHS:
        return method, None
    if method is None or (isinstance(method, str) and method in LINEAR_SOLVERS):
        return "pairs", method
    raise ValueError(f"method must be one of {PATHS + LINEAR_SOLVERS[1:]} or None, got {method!r}")


def _occlusion_mode(occlusion):
    """(exact shadows in the gather, mode of the pairs' visibility: False, "direct", "exact" or
    "sampled") from `solve`'s occlusion argument; True is "direct"."""
    modes = {"exact": (True, "exact"), "sampled": (False, "sampled")}
    if isinstance(occlusion, (bool, np.bool_)):
        return bool(occlusion), ("direct" if occlusion else False)
    if isinstance(occlusion, str) and occlusion in modes:
        return modes[occlusion]
    raise checks.ArgumentTypeError(f'occlusion must be True, False, "exact" or "sampled", got {occlusion!r}')


def _peak_rss_bytes():
    """The process's peak resident memory in bytes, or None where the platform does not say
    (`resource` is POSIX-only: on Windows `import core` must still work)."""
    try:
        import resource
    except ImportError:
        return None
    scale = 1 if sys.platform == "darwin" else 1024  # macOS reports bytes, Linux kibibytes
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale


class _Object:
    """A surface added to a scene, with its material and patch grid."""

    def __init__(self, surface, reflectance, emission, patches, name, two_sided, occluder):
        self.surface = surface
        self.reflectance = reflectance
        self.emission = emission
        self.patches = patches
        self.name = name
        self.two_sided = bool(two_sided)
        self.occluder = bool(occluder)


def _reflectance(value, name="reflectance"):
    rgb = checks.rgb(value, name)
    if np.any(rgb >= 1.0):
        raise ValueError(f"{name} must be < 1 (energy must be absorbed), got {rgb.tolist()}")
    return rgb


CULL_RULES = frozenset({"facing", "shaft", "rows", "columns"})


def _patches(value):
    if value is None:
        return None
    if isinstance(value, (str, bytes)):
        raise checks.ArgumentTypeError(f"patches must be (nu, nv) or an int, got {value!r}")
    if checks.ndim(value, "patches") == 0:
        value = (value, value)
    if checks.ndim(value, "patches") != 1 or len(value) != 2:
        raise ValueError(f"patches must be (nu, nv), got {value!r}")
    nu = checks.count(value[0], "patches nu", limit=checks.MAX_PATCHES)
    nv = checks.count(value[1], "patches nv", limit=checks.MAX_PATCHES)
    if nu * nv > checks.MAX_PATCHES:
        raise ValueError(f"patches {(nu, nv)} is {nu * nv:,} patches: at most {checks.MAX_PATCHES:,}")
    return nu, nv


def _cull_rules(value):
    """The set of culling rules `solve(cull=...)` names (True: all, False or None: none)."""
    if value is True:
        return set(CULL_RULES)
    if value is False or value is None:
        return set()
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise checks.ArgumentTypeError(
            f"cull must be True, False or a set of rule names from {sorted(CULL_RULES)}, got {value!r}"
        )
    rules = set(value)
    unknown = rules - CULL_RULES
    if unknown:
        raise ValueError(
            f"cull has unknown rules {sorted(map(str, unknown))}: known are {sorted(CULL_RULES)}"
        )
    return rules


def _name(value):
    if value is not None and not isinstance(value, str):
        raise checks.ArgumentTypeError(f"name must be a str or None, got {value!r}")
    return value


class Scene:
    """A set of surfaces with materials, and lights; `solve` computes the radiosity."""

    def __init__(self):
        self._objects = []
        self._lights = []
        self._geometry = None  # cached PairCache for the current surfaces and patch grids
        self._pairs = None  # cached pair values, see _PairCache
        self._hierarchical = None  # cached HierarchicalRadiosity (hierarchy and links)
        self._light_cache = {}
        self._extents = {}  # id(surface) -> _extent(surface), for automatic patch grids
        self._sky = np.zeros(3)  # uniform sky radiance (W m^-2 sr^-1, RGB)

    # ---------------------------------------------------------------- inputs
    def add(
        self, surface, reflectance=0.5, emission=0.0, patches=None, name=None, two_sided=False, occluder=True
    ):
        """Add a surface; returns its handle (an int).

        Parameters
        ----------
        surface : Surface or PolygonMesh
            A mesh is one object: its faces' flat pieces (`mesh.PolygonMesh`) are split by
            `patches` each, and it occludes as one triangle BVH.
        reflectance : float or array_like, shape (3,)
            Diffuse reflectance in [0, 1) per channel.
        emission : float or array_like, shape (3,)
            Emitted radiance (or exitance) >= 0 per channel.
        patches : (nu, nv) or int or None
            Split of the parameter domain (patch i * nv + j is cell (i, j), u-major); None
            chooses from the surface's size and the tolerance (for a mesh: one patch per face
            piece).
        name : str, optional
        two_sided : bool
            Both sides reflect and emit (as Blender's mesh faces do); the back side's results are
            `radiosity(h, side="back")`.
        occluder : bool
            Whether the surface blocks light between others (False for Blender's area lights).
        """
        if not isinstance(surface, (Surface, PolygonMesh)):
            raise checks.ArgumentTypeError(
                f"scene.add needs a core surface (Sphere, Quad, PolygonMesh, ...), got {surface!r}"
            )
        two_sided = checks.flag(two_sided, "two_sided") or getattr(surface, "two_sided", False)
        obj = _Object(
            surface,
            _reflectance(reflectance),
            checks.rgb(emission, "emission"),
            _patches(patches),
            _name(name),
            checks.flag(two_sided, "two_sided"),
            checks.flag(occluder, "occluder"),
        )
        self._objects.append(obj)
        self._geometry = None
        return len(self._objects) - 1

    def add_point_light(self, position, intensity, radius=0.0, name=None, soft_falloff=False):
        """Add a point light of radiant intensity (W/sr, scalar or RGB); returns its handle.
        A radius makes it a sphere light, or with `soft_falloff` a disk facing each receiver
        (Cycles' "Soft Falloff"; see `lights.PointLight`)."""
        return self._add_light(PointLight(position, intensity, radius, _name(name), soft_falloff))

    def add_spot_light(
        self, position, direction, intensity, spot_size, spot_blend, radius=0.0, name=None, soft_falloff=False
    ):
        """Add a spot light (Cycles' cone: full angle spot_size, soft edge spot_blend); returns its handle."""
        light = SpotLight(
            position, direction, intensity, spot_size, spot_blend, radius, _name(name), soft_falloff
        )
        return self._add_light(light)

    def add_sun_light(self, direction, irradiance, angle=0.0, name=None):
        """Add a sun: irradiance (W/m^2) on a plane facing it, light travelling along `direction`,
        of angular diameter `angle` (radians, Cycles' sun angle: soft shadows)."""
        return self._add_light(SunLight(direction, irradiance, angle, _name(name)))

    def _add_light(self, light):
        self._lights.append(light)
        return len(self._lights) - 1

    def set_sky(self, radiance):
        """Light the scene by a uniform sky of `radiance` (W m^-2 sr^-1, scalar or RGB; 0: none).

        The sky lies beyond every surface: a point's irradiance from it is pi L times the part
        of its hemisphere (cosine-weighted) that no occluder covers, 1 - sum_j F(x -> j) V(x, j)
        over the occluders' elements (surfaces added with occluder=False, such as area lights,
        let it through, as in Cycles). The back side of a one-sided occluder does not count as
        covering. Form factors are reused: changing the sky is a relight.
        """
        self._sky = checks.rgb(radiance, "sky radiance")

    def materials(self):
        """Copies of what a solution keeps of the scene as solved (later edits do not change
        it): reflectances and emissions per surface (lists of RGB arrays), the lights with their
        powers ([(light, RGB power)]) and the sky's radiance (RGB)."""
        return (
            [o.reflectance.copy() for o in self._objects],
            [o.emission.copy() for o in self._objects],
            [(light, light.power.copy()) for light in self._lights],
            self._sky.copy(),
        )

    def set_material(self, handle, reflectance=None, emission=None):
        """Change a surface's reflectance and/or emission (the next solve reuses form factors)."""
        obj = self._object(handle)
        if reflectance is not None:
            obj.reflectance = _reflectance(reflectance)
        if emission is not None:
            obj.emission = checks.rgb(emission, "emission")

    def set_light(self, handle, intensity=None, irradiance=None):
        """Change a light's intensity (point, spot) or irradiance (sun); shadows are reused."""
        light = self._lights[checks.handle(handle, len(self._lights), "light")]
        if intensity is not None:
            if light.kind == "sun":
                raise ValueError("a sun light has irradiance, not intensity")
            light.intensity = checks.rgb(intensity, "light intensity")
        if irradiance is not None:
            if light.kind != "sun":
                raise ValueError(f"a {light.kind} light has intensity, not irradiance")
            light.irradiance = checks.rgb(irradiance, "sun irradiance")

    def set_surface(self, handle, surface):
        """Replace a surface's geometry; only pairs involving it (and visibility) are recomputed."""
        obj = self._object(handle)
        if not isinstance(surface, (Surface, PolygonMesh)):
            raise checks.ArgumentTypeError(f"set_surface needs a core surface, got {surface!r}")
        obj.surface = surface
        self._geometry = None

    def _object(self, handle):
        return self._objects[checks.handle(handle, len(self._objects), "surface")]

    # ---------------------------------------------------------------- solving
    def solve(
        self,
        tol=1e-3,
        occlusion=True,
        max_bounces=None,
        progress=None,
        cancel=None,
        threads=None,
        method=None,
        cull=True,
        contact_levels=None,
        light_levels=None,
    ):
        """Compute the radiosity of every patch.

        Parameters
        ----------
        tol : float
            Relative accuracy goal: quadrature orders follow it, the iterative solver stops on it.
            Pairs that a horizon may cross (whose fixed outer rule may be off by up to
            KINK_RULE_ERROR) and near pairs (whose first rule may stop early, NEAR_RULE_ERROR)
            are integrated again, adaptively, wherever the solved light shows that error
            (`PairCache.refine_kinks`), and solved again.
        occlusion : bool or {"exact", "sampled"}
            Third-body occlusion (shadows). Exact shadows (`shadow`) apply wherever the target is
            a flat quad, triangle or disk patch and every occluder in the shaft is a sphere,
            ellipsoid or flat polygon; sampled rays elsewhere.
            The solve first samples patch-to-patch visibility with rays (refined where partial,
            balanced to exact totals in enclosures), then, with the radiosities it gives, makes
            exact the visibility of the pairs whose sampled error could show in some patch
            (light-driven: `_picked_by_light`) and solves again.
            True (default): that for the pairs with an emitting patch (direct light, where
            shadows are sharpest; the others keep rays) and exact shadows in
            `Solution.radiosity_at`. "exact": for every pair, so every patch meets tol (slower
            in closed rooms, where much indirect light is partly blocked: BENCHMARKS.md).
            "sampled": rays everywhere (the former behaviour, kept as a reference). False: no
            occlusion.
        max_bounces : int or None
            Inter-reflections to follow (0: emission and direct light only); None: all. The
            solve stops earlier once converged to `tol`, so any count is allowed; counts above
            `solvers.SWEEP_BUDGET` that do not provably converge raise a ValueError.
        progress : callable(stage: str, fraction: float) or None
        cancel : callable() -> bool or None
            Polled between blocks of work; True raises `Cancelled`.
        threads : int or None
            Worker threads (default: min(2, CPU count)); numpy releases the GIL in them.
        method : {None, "pairs", "hierarchical", "direct", "iterative", "gmres", "jacobi"}
            "hierarchical": hierarchical radiosity (`hierarchical`: a patch quadtree per surface,
            links refined until their error meets tol relative to the receiver's radiosity, a
            push-pull solve to the same per-element bound; `form_factor_matrix` is then empty).
            "pairs" (the reference path) or a linear solver for it (None: direct LU up to
            `solvers.DIRECT_SOLVE_LIMIT` elements, GMRES above; "iterative" is GMRES). Every
            element's radiosity meets `tol` relative to its own value (see `solvers`); a solve
            that cannot raises `solvers.ConvergenceError`.
        cull : bool or set of str
            Culling rules to apply ({"facing", "shaft", "rows", "columns"}; True: all). Turning one off
            is for measuring what it saves: results do not change (rays never test the
            convex surface they leave, with or without the "shaft" rule).
        contact_levels : int or None
            Hierarchical path only: quadtree levels below the patches that touch another surface
            across a narrow wedge (a ball resting on a floor; `hierarchy.touching_patches`), so
            that the light there is resolved finer than the patches (a patch's result is the
            area mean of its sub-patches; `radiosity_at` gathers from them), and cells graded
            below them toward the point nearest to the surface touched, down to
            `hierarchy.CONTACT_CELL` of the smaller surface's size (`hierarchy.contact_points`).
            None: `hierarchy.CONTACT_LEVELS`; 0: none (and no grading).
        light_levels : int or None
            Hierarchical path only: quadtree levels below the patches over which the light
            arriving in a first solve varies by more than `hierarchical.LIGHT_VARIATION` of their
            radiosity (a wall lit at grazing angles next to the ceiling, a shadow edge), after
            which the refined tree is linked and solved again (`HierarchicalRadiosity.light_levels`).
            A point gathered next to such a patch (a vertex on a seam, a texel by a shadow)
            then sees its light where it is, not its mean. Toward the sides where another
            surface meets such a patch, on both sides of the seam, the cells narrow further
            (`hierarchical.SEAM_LEVELS` halvings). None: `hierarchical.LIGHT_LEVELS`
            (0: off; it costs about 2x the solve, and the 64,512-patch room of issue 13 went past
            10 minutes with it; 2 is what the add-on's Hierarchical solver asks). With both 0,
            every leaf is a patch, as on the pairs path.

        Returns
        -------
        Solution
        """
        tol = checks.tolerance(tol)
        if not self._objects:
            raise ValueError("the scene is empty: add a surface before solving")
        exact_shadows, mode = _occlusion_mode(occlusion)
        occlusion = mode is not False
        max_bounces = solvers.bounce_count(max_bounces)
        for callback, name in ((progress, "progress"), (cancel, "cancel")):
            if callback is not None and not callable(callback):
                raise checks.ArgumentTypeError(f"{name} must be callable or None, got {callback!r}")
        rules = _cull_rules(cull)
        path, method = _path_and_solver(method)
        levels = dict(contact_levels=contact_levels, light_levels=light_levels)
        for name, value in levels.items():
            if value is not None:
                if path != "hierarchical":
                    raise ValueError(f"{name} applies to method='hierarchical' only")
                levels[name] = checks.count(value, name, 0, MAX_CONTACT_LEVELS)
        grids = self._patch_grids(tol)
        elements = sum(piece_patches(g).sum() * (1 + o.two_sided) for o, g in zip(self._objects, grids))
        if path == "hierarchical" and elements > MAX_HIERARCHICAL_ELEMENTS:
            raise ValueError(
                f"the scene's patches (nu, nv) add up to {elements:,} patches (two-sided surfaces count "
                f"twice): a hierarchical solve takes at most {MAX_HIERARCHICAL_ELEMENTS:,}"
            )
        if path == "pairs" and elements > MAX_ELEMENTS:
            raise ValueError(
                f"the scene's patches (nu, nv) add up to {elements:,} patches (two-sided surfaces count "
                f"twice): at most {MAX_ELEMENTS:,} (about 90 bytes per pair of patches that face each other)"
            )
        run = Run(progress, cancel, threads)
        stats = run.stats
        geometry = self._geometry_for(tol, run, rules, pairs=path == "pairs")
        bvh_start = geometry.occluders.bvh_totals() if geometry.occluders is not None else None
        N = len(geometry.elements)
        owner = geometry.elements.owner
        rho = np.array([o.reflectance for o in self._objects])[owner]
        E = np.array([o.emission for o in self._objects])[owner]

        # direct light from point, spot and sun lights: rho / pi times irradiance
        with run.stage("lights"):
            irradiance = self._direct(geometry, occlusion, tol, run)
        E_total = E + rho * irradiance / np.pi
        sky = self._sky.copy()
        stats["elements"] = N
        if not np.any(E_total > 0) and not (np.any(sky > 0) and np.any(rho > 0)):
            stats["skipped"] = "no emission and no lights: all radiosities are zero"
            solution = Solution(self, geometry, np.zeros((N, 3)), occlusion, tol, stats, run.threads)
            solution.exact_shadows = exact_shadows
            return solution

        if path == "hierarchical":
            runner = self._hierarchical_for(geometry, tol, mode, levels)
            direct = (E, self._irradiance_at(geometry, occlusion, run)) if self._lights else None
            try:
                B, info = runner.solve(
                    np.array([o.reflectance for o in self._objects]), E_total, max_bounces, run, sky, direct
                )
            except solvers.CrossingSurfaceError as error:
                raise self._crossing(error, error.handles, error.row_sums, mode) from error
            stats.update(info, solver="hierarchical", peak_rss_bytes=_peak_rss_bytes())
            stats["memory_bytes"] = info["link_bytes"] + geometry.nbytes()
            run.progress("done", 1.0)
            solution = Solution(self, geometry, B, occlusion, tol, stats, run.threads)
            solution.exact_shadows = exact_shadows
            solution.links_gather = runner.gatherer()
            return solution

        # rows of black patches and columns that carry no light need no form factors
        # (under a sky every occluder's column counts: a black one still covers the sky)
        bright = rho.max(1) > 0
        carries = (E_total.max(1) > 0) | bright
        rows = bright if "rows" in rules else np.ones(N, dtype=bool)
        cols = carries if "columns" in rules and not np.any(sky > 0) else np.ones(N, dtype=bool)
        i, j = geometry.pair_i, geometry.pair_j
        need = (rows[i] & cols[j]) | (rows[j] & cols[i])
        stats["pairs_total"] = N * N
        stats["pairs_culled_facing"] = N * N - geometry.live_ordered
        stats["pairs_culled_rows_columns"] = int(geometry.live_ordered - ordered_pairs(i[need], j[need]))
        stats["rows_skipped"] = int(np.count_nonzero(~rows))
        stats["columns_skipped"] = int(np.count_nonzero(~cols))

        # exact visibility follows for every pair ("exact") or the emitters' ("direct")
        emitters = None if mode == "exact" else E.max(1) > 0
        geometry.compute(np.flatnonzero(need), tol, mode, run, rules, rows, emitters)
        # an element's radiosity is the mean over its part that no face lying on it covers
        # (`coverage`): its direct light too, like its form factors (`matrix`) and sky (`covered`)
        E_direct = E + rho * irradiance * geometry.gather_scale(occlusion)[:, None] / np.pi

        def solve_pairs():
            E_total = E_direct
            # the sky: rho L times the part of each element's hemisphere that no occluder covers
            if np.any(sky > 0):
                with run.stage("lights"):
                    open_sky = np.clip(1.0 - geometry.covered(need, mode), 0.0, 1.0)
                E_total = E_total + rho * open_sky[:, None] * sky[None]
                stats["sky_open_mean"] = float(open_sky[rows].mean()) if rows.any() else 0.0
            # the matrix of needed ordered pairs: F_ij = G / A_i times visibility
            with run.stage("solve"):
                r, c, v, dense = geometry.matrix(need, rows, cols, mode)
                try:
                    B, info = solvers.solve(r, c, v, rho, E_total, tol, max_bounces, method, run.check, dense)
                except ValueError as error:
                    refusal = self._refusal(error, r, v, owner, mode)
                    if refusal is error:
                        raise
                    raise refusal from error
                B[~rows] = E_total[~rows]
            return B, info, (r, c, v)

        B, info, (r, c, v) = solve_pairs()
        # exact visibility where the solved light shows a sampled one's error: every pair
        # ("exact") or the pairs with an emitting element ("direct": where shadows are sharpest)
        changed = mode in ("exact", "direct") and geometry.refine_shadows(
            B, rho, tol, run, rules, rows, emitters
        )
        # kinked and near pairs' form factors likewise, where the solved light shows a first rule's error
        changed = geometry.refine_kinks(B, rho, tol, run, E_direct.max(1) > 0) or changed
        if changed:
            B, info, (r, c, v) = solve_pairs()
        stats.update({k: info[k] for k in ("iterations", "residual", "error_bound", "fallback")})
        stats["solver"] = info["method"]
        stats["matrix_entries"] = int(r.size)
        stats["memory_bytes"] = geometry.nbytes() + r.nbytes + c.nbytes + v.nbytes
        if bvh_start is not None:
            bvh_end = geometry.occluders.bvh_totals()
            stats["bvh_nodes"] = bvh_end["nodes"] - bvh_start["nodes"]
            stats["bvh_primitives"] = bvh_end["primitives"] - bvh_start["primitives"]
        stats["peak_rss_bytes"] = _peak_rss_bytes()
        run.progress("done", 1.0)
        solution = Solution(self, geometry, B, occlusion, tol, stats, run.threads, (r, c, v))
        solution.exact_shadows = exact_shadows
        return solution

    def _geometry_for(self, tol, run, rules, pairs=True):
        """The cached geometry if surfaces and patch grids are unchanged, else a new one
        (`pairs`: with the live pairs of the all-pairs path)."""
        patches = self._patch_grids(tol)
        key = tuple((id(o.surface), o.two_sided, o.occluder, p) for o, p in zip(self._objects, patches))
        old = self._geometry
        if old is not None and old.key == key and old.rules == rules and (old.has_pairs or not pairs):
            run.stats["geometry_cached"] = True
            return old
        with run.stage("elements"):
            geometry = PairCache(self._objects, patches, key, rules, previous=self._pairs, pairs=pairs)
        self._geometry = geometry
        if pairs:
            self._pairs = geometry
        self._light_cache = {}
        self._extents = {}  # id(surface) -> _extent(surface), for automatic patch grids
        run.stats["geometry_cached"] = False
        return geometry

    def _refusal(self, error, rows, values, owner, mode):
        """The error a failed solve raises: `error` itself, its message extended with the surfaces
        whose patches' form factors are not finite or sum above 1 (which no patch's can: the likely
        cause), as a CrossingSurfaceError when the sum is above 1 with occlusion on."""
        bad = np.unique(owner[rows[~np.isfinite(values)]])
        if bad.size:
            names = ", ".join(repr(self._label(o)) for o in bad)
            return ValueError(
                f"{error}; the form factors from the patches of {names} are not finite (a failed integral)"
            )
        total = np.bincount(rows, weights=values, minlength=owner.size)
        handles, row_sums = solvers.overfull(owner, total)
        return self._crossing(error, handles, row_sums, mode) if handles else error

    def _crossing(self, error, handles, row_sums, mode):
        """`error`'s message with the surfaces `handles` named, their patches' largest row sums
        `row_sums` and the likely cause: a CrossingSurfaceError with occlusion on (`mode`), a
        ValueError saying occlusion is off otherwise."""
        names = ", ".join(f"{self._label(o)!r} ({total:.3g})" for o, total in zip(handles, row_sums))
        if not mode:
            cause = "occlusion is off, so surfaces behind others count in full"
            return ValueError(f"{error}; the form factors from the patches of {names} sum above 1: {cause}")
        cause = (
            "a surface that passes through itself or through another (each sees the other side of "
            "the crossing)"
        )
        message = f"{error}; the form factors from the patches of {names} sum above 1: {cause}"
        return solvers.CrossingSurfaceError(message, handles, row_sums)

    def _label(self, handle):
        """Surface `handle`'s name in messages: its own, or "surface <handle>"."""
        return self._objects[handle].name or f"surface {handle}"

    def _hierarchical_for(self, geometry, tol, mode, levels):
        """The cached hierarchy and links if geometry, tol, occlusion mode and sub-patch levels
        (dict of `contact_levels`, `light_levels`) are unchanged."""
        key = (float(tol), mode, tuple(sorted(levels.items())))
        cached = self._hierarchical
        if cached is not None and cached[0] is geometry and cached[1] == key:
            return cached[2]
        sides, halves = [], []  # (halves: what each tree is of its surface, `hclosure`)
        for k, (obj, grid, (start, count, two_sided)) in enumerate(
            zip(self._objects, geometry.objects_grid, geometry.ranges)
        ):
            # a mesh is one tree per flat piece (each piece's patches are consecutive elements)
            if isinstance(obj.surface, PolygonMesh):
                pieces, grids = obj.surface.pieces(), [tuple(g) for g in np.reshape(grid, (-1, 2))]
            else:
                pieces, grids = [obj.surface], [grid]
            offsets = np.concatenate([[0], np.cumsum([nu * nv for nu, nv in grids])])
            for piece, piece_grid, offset in zip(pieces, grids, offsets):
                sides.append((piece, k, piece_grid, start + int(offset)))
                halves.append(FRONT_HALF if two_sided else ONE_SIDED)
                if two_sided:
                    sides.append((piece.flipped(), k, piece_grid, start + count + int(offset)))
                    halves.append(BACK_HALF)
        occluders = geometry.occluders if mode else None
        runner = HierarchicalRadiosity(
            sides, occluders, geometry.occluder_object, tol, mode, halves=halves, **levels
        )
        self._hierarchical = (geometry, key, runner)
        geometry.link_visibility = runner.known_visibility
        return runner

    def _patch_grids(self, tol):
        """Each object's (nu, nv): given, or from its size relative to the scene's (a mesh: one
        (nu, nv) per piece, a tuple of them)."""
        grids = [o.patches for o in self._objects]
        if all(g is not None for g in grids):
            return [_mesh_grid(o.surface, g, None) for o, g in zip(self._objects, grids)]
        for o in self._objects:  # (surfaces are kept by their objects, so ids stay theirs)
            if id(o.surface) not in self._extents:
                self._extents[id(o.surface)] = _extent(o.surface)
        boxes = [self._extents[id(o.surface)] for o in self._objects]
        lo = np.min([b[0] for b in boxes], axis=0)
        hi = np.max([b[1] for b in boxes], axis=0)
        target = AUTO_PATCH_SIZE * np.linalg.norm(hi - lo) * (tol / 1e-3) ** 0.25
        out = []
        for o, g, box in zip(self._objects, grids, boxes):
            if isinstance(o.surface, PolygonMesh):
                g = _mesh_grid(o.surface, g, target)
            elif g is None:
                lu, lv = box[2], box[3]
                g = tuple(
                    int(np.clip(np.ceil(x / max(target, 1e-300)), 1, MAX_AUTO_PATCHES)) for x in (lu, lv)
                )
            out.append(g)
        return out

    def _irradiance_at(self, geometry, occlusion, run):
        """Irradiance from the point, spot and sun lights at points of elements: a callable
        (x (K, 3), unit normals n (K, 3), element (K,)) -> (K, 3), with shadows as in `_direct`."""
        lights = list(self._lights)

        def irradiance(x, n, element):
            total = np.zeros((len(x), 3))
            for light in lights:
                value = light.unshadowed(x, n)
                if occlusion and geometry.shafts is not None:
                    value = value * geometry.light_visibility(light, x, n, element, value > 0, run)
                total += value[:, None] * light.power[None]
            return total

        return irradiance

    def _direct(self, geometry, occlusion, tol, run):
        """Patch-average irradiance from the point, spot and sun lights, shape (N, 3)."""
        N = len(geometry.elements)
        total = np.zeros((N, 3))
        for light in self._lights:
            key = light.geometry_key() + (occlusion, float(tol))
            if key not in self._light_cache:
                self._light_cache[key] = geometry.light_factors(light, occlusion, run, tol)
            total += self._light_cache[key][:, None] * light.power[None]
        return total


def _mesh_grid(surface, grid, target):
    """A mesh's patch grid per piece, a tuple of (nu, nv): `grid` for every piece, or (None) from
    each piece's mean edge lengths along u and v and the target patch size (m); other surfaces'
    grids are returned as they are."""
    if not isinstance(surface, PolygonMesh):
        return grid
    if grid is not None:
        return (tuple(grid),) * len(surface.piece_face)
    c = surface.piece_corners
    along_u = 0.5 * (np.linalg.norm(c[:, 1] - c[:, 0], axis=1) + np.linalg.norm(c[:, 2] - c[:, 3], axis=1))
    along_v = 0.5 * (np.linalg.norm(c[:, 3] - c[:, 0], axis=1) + np.linalg.norm(c[:, 2] - c[:, 1], axis=1))
    n = np.clip(np.ceil(np.stack([along_u, along_v], 1) / max(target, 1e-300)), 1, MAX_AUTO_PATCHES)
    return tuple(map(tuple, n.astype(int).tolist()))


def _extent(surface, m=9):
    """(box min, box max, mean length along u, mean length along v) from an m x m grid."""
    if isinstance(surface, PolygonMesh):
        return surface.vertices.min(0), surface.vertices.max(0), 0.0, 0.0
    (u0, u1), (v0, v1) = surface.domain
    u, v = np.meshgrid(np.linspace(u0, u1, m), np.linspace(v0, v1, m), indexing="ij")
    P, _ = surface.evaluate(u, v)
    along_u = np.linalg.norm(np.diff(P, axis=0), axis=-1).sum(0).mean()
    along_v = np.linalg.norm(np.diff(P, axis=1), axis=-1).sum(1).mean()
    return P.reshape(-1, 3).min(0), P.reshape(-1, 3).max(0), along_u, along_v
