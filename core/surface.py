"""The parametric surface patch: a shared geometry restricted to a box of its parameters.

Conventions used throughout the core:

- xyz is the trailing axis; parameters u, v are arrays of any (broadcastable) shape S, and
  points, tangents and normals come back with shape S + (3,).
- The *normal* of a patch is the unnormalised front normal: its direction is the front side and
  its length is the area density |dP/du x dP/dv| (m^2 per unit of u times unit of v).
- A `Geometry` is immutable and shared by every patch cut from it (`subpatch`, `split`,
  `flipped`), so a scene with many patches of one object holds one geometry.
"""

import numpy as np

from . import checks
from .kinds import GENERIC

AREA_RTOL = 1e-8  # relative accuracy an integrated area must reach (else a ValueError)
DOMAIN_SLACK = 1e-9  # parameters this far outside the box (relative to its width) are still inside


class Geometry:
    """World-space shape P(u, v) with first derivatives; subclasses define the shape.

    Attributes
    ----------
    natural_domain : tuple ((u0, u1), (v0, v1))
        The full parameter range.
    handedness : {+1, -1}
        -1 after an odd number of mirroring transforms; the front normal is multiplied by it
        so that the image of the front side stays the front side.
    """

    natural_domain = ((0.0, 1.0), (0.0, 1.0))
    handedness = 1

    @property
    def kind(self):
        """The shape's family (`core.kinds`): which exact ray test applies to it (GENERIC: none,
        it occludes through a proxy mesh)."""
        return GENERIC

    def exact_kind(self, box):
        """Which closed form (`core.kinds`) gives F(point -> the patch over `box`), GENERIC if none."""
        return GENERIC

    def whole_ellipsoid(self, box):
        """True when the patch over `box` is a whole ellipsoid (a sphere under any affine map)."""
        return False

    def hull_points(self, box):
        """Points, shape (H, 3), whose convex hull holds the patch over `box`, or None."""
        return None

    def bounded_solid(self):
        """(centre (3,), linear (3, 3)) of the ellipsoid {centre + linear p : |p| <= 1} whose whole
        boundary this geometry is over its natural domain (a sphere under any affine map), or
        None."""
        return None

    def derivatives(self, u, v):
        """Points and first derivatives.

        Parameters
        ----------
        u, v : ndarray, broadcastable to shape S

        Returns
        -------
        P, Pu, Pv : ndarray, shape S + (3,)
            Position (m) and dP/du, dP/dv.
        """
        raise NotImplementedError

    def transformed(self, linear, offset):
        """The image of this geometry under x -> linear @ x + offset."""
        raise NotImplementedError

    def exact_area(self, box):
        """Area of the parameter box ((u0, u1), (v0, v1)) in closed form, or None if unknown."""
        return None

    @property
    def plane(self):
        """(origin, unit normal) of the plane holding the whole geometry, or None if curved."""
        return None

    @property
    def convex_outward(self):
        """True if, with orientation +1, the front is the outside of a convex body's boundary.

        No two points of such a geometry face each other, so its outward patches never
        exchange light among themselves (the outside of a sphere, ellipsoid or cylinder).
        """
        return False

    @property
    def breaks(self):
        """Parameters (u values, v values) of lines across which P may not be analytic.

        Rules that assume an analytic integrand along a curve (`cellcontour`) are not used on
        cells that straddle one. Analytic shapes have none; NURBS have their interior knots.
        """
        return np.zeros(0), np.zeros(0)

    def validate_box(self, box):
        """Raise ValueError if the patch over `box` has zero area or is otherwise degenerate."""

    @classmethod
    def stack(cls, geometries):
        """The parameters of many geometries of this class, arranged once for `stacked_derivatives`
        (here: the list itself)."""
        return list(geometries)

    @classmethod
    def stacked_derivatives(cls, stack, index, u, v):
        """Evaluate many geometries of this class at once.

        Parameters
        ----------
        stack : the `stack` of G geometries
        index : ndarray of int, shape (K,)
            Which geometry each point belongs to.
        u, v : ndarray, shape (K,)

        Returns
        -------
        P, Pu, Pv : ndarray, shape (K, 3)
        """
        P = np.empty((index.size, 3))
        Pu = np.empty((index.size, 3))
        Pv = np.empty((index.size, 3))
        for g in np.unique(index):
            sel = np.flatnonzero(index == g)
            P[sel], Pu[sel], Pv[sel] = stack[g].derivatives(u[sel], v[sel])
        return P, Pu, Pv


class AffineGeometry(Geometry):
    """A canonical local shape mapped to the world by x = linear @ p + offset.

    Subclasses implement `local_jet(u, v)` as a staticmethod on arrays: p, dp/du and dp/dv of
    the canonical shape in one array of shape S + (3, 3) (so that the map to the world is one
    matrix product, not three).
    """

    def __init__(self, linear, offset):
        self.linear = np.array(linear, dtype=np.float64)
        self.offset = np.array(offset, dtype=np.float64)
        self.handedness = 1 if np.linalg.det(self.linear) > 0 else -1
        for a in (self.linear, self.offset):
            a.setflags(write=False)
        self._similarity = ()  # `similarity_scale`, computed on first use (the map is read-only)

    @staticmethod
    def local_jet(u, v):
        """Canonical point and derivatives, shape S + (3, 3): [..., 0, :] = p, [..., 1, :] = dp/du,
        [..., 2, :] = dp/dv, for u, v of one shape S."""
        raise NotImplementedError

    def unit_box(self, box):
        """(lo, hi), shape (3,) each: a box holding the canonical shape over `box`."""
        raise NotImplementedError

    @classmethod
    def local(cls, u, v):
        """Canonical p, dp/du, dp/dv, each shape S + (3,) (views of `local_jet`)."""
        jet = cls.local_jet(u, v)
        return jet[..., 0, :], jet[..., 1, :], jet[..., 2, :]

    def derivatives(self, u, v):
        u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
        world = self.local_jet(u, v) @ self.linear.T
        return world[..., 0, :] + self.offset, world[..., 1, :], world[..., 2, :]

    def transformed(self, linear, offset):
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        AffineGeometry.__init__(new, linear @ self.linear, linear @ self.offset + offset)
        return new

    @property
    def similarity_scale(self):
        """s if linear = s * (orthogonal matrix), else None."""
        if self._similarity == ():
            gram = self.linear.T @ self.linear
            s2 = np.trace(gram) / 3.0
            similar = np.abs(gram - s2 * np.eye(3)).max() <= 1e-12 * s2
            self._similarity = float(np.sqrt(s2)) if similar else None
        return self._similarity

    @classmethod
    def stack(cls, geometries):
        """(linear, offset) of every geometry, shapes (G, 3, 3) and (G, 3)."""
        return np.stack([g.linear for g in geometries]), np.stack([g.offset for g in geometries])

    @classmethod
    def stacked_derivatives(cls, stack, index, u, v):
        jet = cls.local_jet(u, v)  # (K, 3, 3)
        if len(stack[0]) == 1:  # one geometry: one matrix product, no gather
            world = jet @ stack[0][0].T
            return world[:, 0] + stack[1][0], world[:, 1], world[:, 2]
        world = np.einsum("kij,kmj->kmi", stack[0][index], jet)
        return world[:, 0] + stack[1][index], world[:, 1], world[:, 2]


class Surface:
    """A parametric patch: P(u, v) for (u, v) in `domain`, front side given by `evaluate`'s normal.

    Build one through a subclass (`Sphere`, `Quad`, `Disk`, `Cylinder`, `NurbsSurface`);
    `subpatch`, `split`, `flipped` and `transformed` return new patches of the same class.
    """

    def _init(self, geometry, box=None, sign=1):
        self.geometry = geometry
        (u0, u1), (v0, v1) = box if box is not None else geometry.natural_domain
        self._box = ((float(u0), float(u1)), (float(v0), float(v1)))
        self._sign = 1 if sign > 0 else -1
        self._area = None

    @classmethod
    def _make(cls, geometry, box=None, sign=1):
        patch = object.__new__(cls)
        patch._init(geometry, box, sign)
        geometry.validate_box(patch._box)
        return patch

    # ---------------------------------------------------------------- evaluation
    @property
    def domain(self):
        """((u0, u1), (v0, v1)): the parameter box of this patch."""
        return self._box

    @property
    def orientation(self):
        """+1 or -1: the factor applied to dP/du x dP/dv to get the front normal."""
        return self._sign * self.geometry.handedness

    @property
    def is_flipped(self):
        """True for the other side of the geometry's own front (`flipped` an odd number of times):
        for a sphere, ellipsoid or cylinder its inside."""
        return self._sign < 0

    def derivatives(self, u, v):
        """Points and parameter derivatives; see `Geometry.derivatives` for shapes."""
        return self.geometry.derivatives(u, v)

    def evaluate(self, u, v):
        """Points and unnormalised front normals.

        Parameters
        ----------
        u, v : array_like, broadcastable to shape S
            Parameters inside `domain` (to DOMAIN_SLACK of its width).

        Returns
        -------
        points : ndarray, shape S + (3,)
            Positions (m).
        normals : ndarray, shape S + (3,)
            Front normal with length = area density |dP/du x dP/dv| (m^2 per unit u per unit v).

        Raises
        ------
        ValueError
            A parameter that is not finite or lies outside `domain` (a surface would otherwise
            be extended or clamped there silently).
        """
        u, v = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
        for name, t, (lo, hi) in (("u", u, self._box[0]), ("v", v, self._box[1])):
            slack = DOMAIN_SLACK * (hi - lo)
            inside = (t >= lo - slack) & (t <= hi + slack)  # (False for NaN)
            if not inside.all():
                bad = t[~inside].ravel()[0]
                raise ValueError(f"{name} = {bad!r} is outside the domain [{lo!r}, {hi!r}] of {self!r}")
        P, Pu, Pv = self.geometry.derivatives(u, v)
        normal = np.cross(Pu, Pv)
        if self.orientation < 0:
            normal = -normal
        return P, normal

    def area(self):
        """Surface area (m^2), exact where a closed form exists, else by adaptive quadrature."""
        if self._area is None:
            exact = self.geometry.exact_area(self._box)
            if exact is None:
                from .integrate import integrate_box

                def density(u, v):
                    return np.linalg.norm(self.evaluate(u, v)[1], axis=-1)

                exact, error, _ = integrate_box(density, self._box, rtol=1e-13)
                if not error <= AREA_RTOL * abs(exact):
                    raise ValueError(
                        f"the area of {self!r} could not be integrated to {AREA_RTOL:g} within the work "
                        f"budget: reached {exact!r} with an estimated error of {error:.3g}"
                    )
            self._area = float(exact)
        return self._area

    # ---------------------------------------------------------------- new patches
    def subpatch(self, u=None, v=None):
        """The part of this patch over u in (a, b) and v in (c, d); an omitted range stays whole.

        Raises
        ------
        ValueError
            If a range is not increasing, leaves this patch's domain, is narrower than float64
            resolves (`checks.interval`), or gives a patch too small for its position
            (`check_scale`).
        """
        (u0, u1), (v0, v1) = self._box
        ub = checks.interval(u, "u", (u0, u1)) if u is not None else (u0, u1)
        vb = checks.interval(v, "v", (v0, v1)) if v is not None else (v0, v1)
        patch = type(self)._make(self.geometry, (ub, vb), self._sign)
        patch.check_scale(f"subpatch(u={ub}, v={vb})")
        return patch

    def split(self, nu, nv):
        """nu x nv equal parameter sub-patches, listed u-major: index i * nv + j for cell (i, j).

        Raises
        ------
        ValueError
            If nu or nv is not a positive integer, nu * nv exceeds `checks.MAX_PATCHES`, or the
            cells would be narrower than float64 resolves (`checks.interval`).
        """
        nu = checks.count(nu, "nu", limit=checks.MAX_PATCHES)
        nv = checks.count(nv, "nv", limit=checks.MAX_PATCHES)
        if nu * nv > checks.MAX_PATCHES:
            raise ValueError(
                f"split({nu}, {nv}) asks for {nu * nv:,} patches: at most {checks.MAX_PATCHES:,} per split"
            )
        (u0, u1), (v0, v1) = self._box
        for name, n, (a, b) in (("nu", nu, (u0, u1)), ("nv", nv, (v0, v1))):
            if (b - a) / n < checks.RESOLUTION * max(abs(a), abs(b)):
                raise ValueError(
                    f"split: {name} = {n} cuts the range ({a!r}, {b!r}) into cells narrower than "
                    f"{checks.RESOLUTION:.0e} of its values, too narrow for float64"
                )
        us = np.linspace(u0, u1, nu + 1)
        vs = np.linspace(v0, v1, nv + 1)
        return [
            type(self)._make(self.geometry, ((us[i], us[i + 1]), (vs[j], vs[j + 1])), self._sign)
            for i in range(nu)
            for j in range(nv)
        ]

    def flipped(self):
        """Same geometry and parameters, with the other side as front."""
        return type(self)._make(self.geometry, self._box, -self._sign)

    def transformed(self, matrix):
        """The image under a 4x4 affine matrix (column vectors: x' = M @ [x, 1]).

        The image of the front side stays the front side (so a mirrored sphere is still seen
        from outside); a non-uniform scale turns a sphere into an ellipsoid.
        """
        linear, offset = checks.affine(matrix)
        image = type(self)._make(self.geometry.transformed(linear, offset), self._box, self._sign)
        image.check_scale("surface after the transform matrix")
        return image

    def check_scale(self, name, m=5):
        """Raise ValueError if float64 cannot represent this patch meaningfully.

        The patch is sampled on an m x m parameter grid: its points must lie within
        `checks.MAX_COORDINATE` of the origin, and its smaller extent (the longest grid line
        along u or along v, whichever is shorter) must pass `checks.resolvable` against its
        distance from the origin.

        Parameters
        ----------
        name : str
            What the message calls the patch.
        m : int
            Grid points per parameter.
        """
        (u0, u1), (v0, v1) = self._box
        u, v = np.meshgrid(np.linspace(u0, u1, m), np.linspace(v0, v1, m), indexing="ij")
        P = self.geometry.derivatives(u, v)[0]
        checks.coordinates(P, name)
        position = float(np.linalg.norm(P, axis=-1).max())
        along_u = np.linalg.norm(np.diff(P, axis=0), axis=-1).sum(0).max()
        along_v = np.linalg.norm(np.diff(P, axis=1), axis=-1).sum(1).max()
        checks.resolvable(float(min(along_u, along_v)), position, f"{name} (its smaller extent)")

    def __repr__(self):
        (u0, u1), (v0, v1) = self._box
        side = "" if self._sign > 0 else ", flipped"
        return f"{type(self).__name__}(u=({u0:.6g}, {u1:.6g}), v=({v0:.6g}, {v1:.6g}){side})"


def translated(surfaces, offset):
    """The patches moved by `offset`, keeping what they share.

    Patches that share a geometry share its moved copy, and a patch listed twice stays one
    object, so every relation between them (parts of one body, a self pair) is kept.

    Parameters
    ----------
    surfaces : sequence of Surface
    offset : array_like, shape (3,)
        Translation (m).

    Returns
    -------
    list of Surface
        Same order and length as `surfaces`.
    """
    offset = np.asarray(offset, dtype=np.float64)
    geometries, patches, out = {}, {}, []
    for patch in surfaces:
        if id(patch) not in patches:
            key = id(patch.geometry)
            if key not in geometries:
                geometries[key] = patch.geometry.transformed(np.eye(3), offset)
            patches[id(patch)] = type(patch)._make(geometries[key], patch._box, patch._sign)
        out.append(patches[id(patch)])
    return out


def nearest_step(x, P, Pu, Pv):
    """One Gauss-Newton step toward the parameters of the surface point nearest to x.

    Minimises |P(u, v) - x|^2 through the normal equations of J = [dP/du, dP/dv]; a singular J
    (a pole) is regularised by a ridge of 1e-12 of its trace.

    Parameters
    ----------
    x, P, Pu, Pv : ndarray, shape (K, 3)
        Target points, and the surface's points and derivatives at the current parameters.

    Returns
    -------
    du, dv : ndarray, shape (K,)
    """
    r = x - P
    a = np.einsum("kj,kj->k", Pu, Pu)
    b = np.einsum("kj,kj->k", Pu, Pv)
    c = np.einsum("kj,kj->k", Pv, Pv)
    g1 = np.einsum("kj,kj->k", Pu, r)
    g2 = np.einsum("kj,kj->k", Pv, r)
    ridge = 1e-12 * (a + c) + 1e-300
    a, c = a + ridge, c + ridge
    det = a * c - b * b
    return (c * g1 - b * g2) / det, (a * g2 - b * g1) / det
