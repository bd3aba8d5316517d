"""Reference diffuse view factors (configuration factors) with their sources, and concrete test cases.

Convention (the project's): for surfaces 1 and 2 with front normals n1, n2,

    F(1 -> 2) = 1 / (pi A1) * integral_{A1} integral_{A2} max(0, cos1) max(0, cos2) / L^2 dA2 dA1,

a pair of points counting only where each lies in front of the other, with NO occlusion by any third
body. F(s -> s) of a concave surface is its self factor.

Every catalogue formula below is a closed form from the literature, evaluated in mpmath at 40
significant digits (several of them lose all their digits to cancellation in double precision for small
or distant surfaces), or a rigorously derived one-dimensional integral evaluated to ~1e-15 with
`mpmath.quad`, as stated in its docstring. Sources were looked up in public copies; where a formula was
transcribed from public code that cites the catalogue, the citation names that code as well.

Abbreviations used in the sources:

- Howell, catalogue: J. R. Howell, "A Catalog of Radiation Heat Transfer Configuration Factors",
  on-line 3rd ed., www.thermalradiation.net (case numbers B-xx: element to area, C-xx: area to area);
  printed edition: McGraw-Hill, 1982.
- S&H: R. Siegel and J. R. Howell, "Thermal Radiation Heat Transfer" (4th ed. pages are quoted by
  F-Chart's EES heat-transfer library documentation).
- F&G: A. Feingold and K. G. Gupta, J. Heat Transfer 92:69-76 (1970), the reference of Howell's
  sphere-to-plane-figure pages C-121 and C-124 (their formulas are images; only the titles and
  definitions could be read, so no formula here is transcribed from them).
- EES: F-Chart Software, EES heat transfer library, "shape factors" pages (fchartsoftware.com/ees/
  heat_transfer_library/shape_factors/hs*.htm), each with a worked numerical example quoted here and
  re-checked in tests/test_reference_catalog.py.

`CASES` lists concrete configurations built from the project's surfaces (`core.Sphere`, `core.Quad`,
`core.Disk`, `core.Cylinder`); each `Case.build()` returns `(src, dst)` and `Case.exact` is
F(src -> dst) under the convention above. tests/reference/check_catalog.py re-estimates every case by
brute force (randomised quasi-Monte Carlo of the 4D integral, using only `Surface.evaluate`).
"""

from dataclasses import dataclass
from typing import Callable

import mpmath as mp
import numpy as np

import core

_DPS = 40

# ======================================================================================== helpers


def _f(x):
    return float(x)


def solid_angle_triangle(p, a, b, c):
    """Solid angle (sr) of the flat triangle abc seen from the point p (unsigned).

    Van Oosterom & Strackee, "The solid angle of a plane triangle", IEEE Trans. Biomed. Eng. 30:125
    (1983): with R_i = vertex_i - p and r_i = |R_i|,

        tan(Omega / 2) = |R1 . (R2 x R3)| / (r1 r2 r3 + (R1.R2) r3 + (R1.R3) r2 + (R2.R3) r1).

    Exact for any triangle not containing p; evaluated with atan2 at 40 digits.
    """
    with mp.workdps(_DPS):
        R = [mp.matrix([mp.mpf(float(x)) - mp.mpf(float(y)) for x, y in zip(v, p)]) for v in (a, b, c)]

        def dot(x, y):
            return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]

        def cross(x, y):
            return mp.matrix(
                [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]
            )

        r = [mp.sqrt(dot(v, v)) for v in R]
        num = abs(dot(R[0], cross(R[1], R[2])))
        den = r[0] * r[1] * r[2] + dot(R[0], R[1]) * r[2] + dot(R[0], R[2]) * r[1] + dot(R[1], R[2]) * r[0]
        return 2 * mp.atan2(num, den)


# =========================================================================== sphere to flat shapes


def sphere_to_rectangle_corner(l1, l2, d):
    """Sphere to a rectangle l1 x l2 whose corner lies at the foot of the normal through the sphere centre.

    F = 1 / (4 pi) * atan( l1 l2 / (d sqrt(l1^2 + l2^2 + d^2)) )
      = 1 / (4 pi) * atan( 1 / sqrt(D1^2 + D2^2 + D1^2 D2^2) ),   D1 = d / l1, D2 = d / l2,

    independent of the sphere radius r. It is the solid angle of the rectangle seen from the sphere
    centre divided by 4 pi.

    Source: EES f3d_7 "Sphere to finite plane" (hs207), citing Tripp, Hwang & Crank, Kansas State Univ.
    Bull. 46(4), Spec. Rept. 16 (1962), in Howell's printed catalogue (1982) p. 190; worked example
    l1 = l2 = d = 0.5 -> 0.04167 (= 1/24). Howell catalogue C-121 (sphere to rectangle, F&G) and C-124
    (sphere to any polygon by configuration algebra) give the same geometry class.

    Valid for a front-facing rectangle (its front on the sphere's side) in a plane that does not cut the
    sphere: r <= d; the rectangle may extend anywhere in its plane.
    """
    if l1 == 0 or l2 == 0:
        return 0.0
    with mp.workdps(_DPS):
        l1, l2, d = mp.mpf(l1), mp.mpf(l2), mp.mpf(d)
        return _f(mp.atan(l1 * l2 / (d * mp.sqrt(l1 * l1 + l2 * l2 + d * d))) / (4 * mp.pi))


def sphere_to_rectangle(x1, x2, y1, y2, d):
    """Sphere centred at (0, 0, d) to the rectangle [x1, x2] x [y1, y2] in the plane z = 0 (front +z).

    Superposition of `sphere_to_rectangle_corner` over the four corner rectangles with signs
    (configuration-factor algebra; Howell catalogue C-124, F&G):

        F = G(x2, y2) - G(x1, y2) - G(x2, y1) + G(x1, y1),
        G(x, y) = sign(x) sign(y) sphere_to_rectangle_corner(|x|, |y|, d).

    Exact for any axis-aligned rectangle position (centre above, outside or straddling the rectangle)
    as long as r <= d.
    """

    def g(x, y):
        return np.sign(x) * np.sign(y) * sphere_to_rectangle_corner(abs(x), abs(y), d)

    return float(g(x2, y2) - g(x1, y2) - g(x2, y1) + g(x1, y1))


def sphere_above_square_centre(a, b):
    """Sphere (any radius r < a) centred at height a above the centre of a square of side b.

    F = 4 sphere_to_rectangle_corner(b/2, b/2, a) = (1/pi) atan( (b/2)^2 / (a sqrt(a^2 + 2 (b/2)^2)) ).

    The project's seed case: a = b = 6 gives 0.0640942168489749 (= atan(1/sqrt(24)) / pi).
    Source: as `sphere_to_rectangle_corner` (four corner rectangles, configuration algebra).
    """
    with mp.workdps(_DPS):
        a, h = mp.mpf(a), mp.mpf(b) / 2
        return _f(mp.atan(h * h / (a * mp.sqrt(a * a + 2 * h * h))) / mp.pi)


def sphere_to_triangle(center, a, b, c):
    """Sphere (centre `center`) to a flat triangle abc whose front faces the sphere: Omega / (4 pi).

    The sphere-to-plane-figure factor is the solid angle of the figure seen from the sphere centre
    over 4 pi (the basis of F&G's method; Howell catalogue C-123 sphere to triangle, C-124 sphere to any
    polygon by adding triangles); Omega from Van Oosterom & Strackee (see `solid_angle_triangle`).
    Valid when the triangle's plane does not cut the sphere.
    """
    with mp.workdps(_DPS):
        return _f(solid_angle_triangle(center, a, b, c) / (4 * mp.pi))


def sphere_to_coaxial_disk(R, h):
    """Sphere centred on the axis of a disk of radius R at distance h from it (disk front faces the sphere).

    F = (1/2) (1 - 1 / sqrt(1 + (R/h)^2)) = R^2 / (2 sqrt(h^2 + R^2) (sqrt(h^2 + R^2) + h)),

    the second form free of cancellation. Independent of the sphere radius (r <= h).
    Source: EES f3d_16 "Sphere to disk" (hs216), citing Rohsenow et al., Handbook of Heat Transfer,
    3rd ed., p. 7.84; worked example R = 1, h = 0.5 -> 0.2764. Point-source limit R << h:
    F -> R^2 / (4 h^2) = A_disk / (4 pi h^2).
    """
    with mp.workdps(_DPS):
        R, h = mp.mpf(R), mp.mpf(h)
        s = mp.sqrt(h * h + R * R)
        return _f(R * R / (2 * s * (s + h)))


def sphere_to_coaxial_annulus(r_in, r_out, h):
    """Sphere on the axis of an annulus r_in <= rho <= r_out at distance h: difference of two disks.

    Configuration algebra on `sphere_to_coaxial_disk` (same source and validity).
    """
    with mp.workdps(_DPS):
        return sphere_to_coaxial_disk(r_out, h) - sphere_to_coaxial_disk(r_in, h)


def disk_to_coaxial_sphere(R, h, r):
    """Disk of radius R (front towards the sphere) to a sphere of radius r centred on its axis at h.

    Reciprocity: F = (4 pi r^2) / (pi R^2) * sphere_to_coaxial_disk(R, h) = 4 r^2 / R^2 * F_sd.
    Valid for r <= h (sphere entirely in front of the disk plane).
    """
    return 4.0 * r * r / (R * R) * sphere_to_coaxial_disk(R, h)


def sphere_to_coaxial_ellipse(a, b, h):
    """Sphere centred at height h above the centre of a flat ellipse with semi-axes a, b (front up).

    Derived here: F = Omega / (4 pi) (as for any plane figure, see `sphere_to_triangle`), and in polar
    coordinates about the foot of the axis the solid angle of a star-shaped plane region is

        Omega = integral_0^{2 pi} (1 - h / sqrt(h^2 + rho(phi)^2)) dphi,
        rho(phi) = a b / sqrt(b^2 cos^2 phi + a^2 sin^2 phi)   (ellipse boundary),

    a smooth periodic integrand, integrated with mpmath.quad over [0, pi/2] (times 4, by symmetry) to
    ~1e-20. For a = b it is `sphere_to_coaxial_disk`. Valid for sphere radius r <= h.
    This is the image of a disk under a non-uniform scaling diag(a/R, b/R, 1).
    """
    with mp.workdps(_DPS):
        a, b, h = mp.mpf(a), mp.mpf(b), mp.mpf(h)

        def integrand(phi):
            rho2 = (a * b) ** 2 / ((b * mp.cos(phi)) ** 2 + (a * mp.sin(phi)) ** 2)
            s = mp.sqrt(h * h + rho2)
            return rho2 / (s * (s + h))  # = 1 - h / s without cancellation

        omega = 4 * mp.quad(integrand, [0, mp.pi / 4, mp.pi / 2])
        return _f(omega / (4 * mp.pi))


# ================================================================================ flat to flat


def parallel_rectangles(a, b, c):
    """C-11: identical, parallel, directly opposed rectangles a x b at distance c (fronts facing).

    X = a/c, Y = b/c,
    F = 2 / (pi X Y) * [ ln sqrt((1 + X^2)(1 + Y^2) / (1 + X^2 + Y^2))
                         + X sqrt(1 + Y^2) atan(X / sqrt(1 + Y^2)) + Y sqrt(1 + X^2) atan(Y / sqrt(1 + X^2))
                         - X atan X - Y atan Y ].

    Source: Howell catalogue C-11 (Hottel 1931; Hamilton & Morgan 1952), as transcribed with that
    citation in public code (matt77hias/ffpy, src/formfactor.py, ff_parallel_3D); EES f3d_1 (S&H 4th ed.
    p. 843) example a = 1, b = 1.5, c = 0.5 -> 0.4756. Evaluated at 40 digits: for tiny or far
    rectangles (X, Y ~ 1e-4) the bracket cancels to ~X^2 Y^2 and double precision gives no digit.
    Limit X, Y -> 0: F -> a b / (pi c^2).
    """
    with mp.workdps(_DPS + 20):
        a, b, c = mp.mpf(a), mp.mpf(b), mp.mpf(c)
        X, Y = a / c, b / c
        X2, Y2 = X * X, Y * Y
        bracket = (
            mp.log((1 + X2) * (1 + Y2) / (1 + X2 + Y2)) / 2
            + X * mp.sqrt(1 + Y2) * mp.atan(X / mp.sqrt(1 + Y2))
            + Y * mp.sqrt(1 + X2) * mp.atan(Y / mp.sqrt(1 + X2))
            - X * mp.atan(X)
            - Y * mp.atan(Y)
        )
        return _f(2 / (mp.pi * X * Y) * bracket)


def perpendicular_rectangles(w, edge, h):
    """C-14: rectangle 1 (w x edge) to rectangle 2 (h x edge) sharing the edge, at 90 degrees.

    W = w/edge, H = h/edge,
    F(1 -> 2) = 1 / (pi W) * [ W atan(1/W) + H atan(1/H) - sqrt(H^2 + W^2) atan(1 / sqrt(H^2 + W^2))
        + 1/4 ln{ (1 + W^2)(1 + H^2) / (1 + W^2 + H^2)
                  * [W^2 (1 + W^2 + H^2) / ((1 + W^2)(W^2 + H^2))]^(W^2)
                  * [H^2 (1 + H^2 + W^2) / ((1 + H^2)(H^2 + W^2))]^(H^2) } ].

    Source: Howell catalogue C-14 (Hottel 1931; Hamilton & Morgan 1952), as transcribed with that
    citation in public code (matt77hias/ffpy, ff_orthogonal_3D). Fronts face each other (inside of
    the dihedral). Unit squares: 0.2000438...; the cube rule C-11 + 4 C-14 = 1 is checked in
    tests/test_reference_catalog.py.
    """
    with mp.workdps(_DPS):
        W, H = mp.mpf(w) / mp.mpf(edge), mp.mpf(h) / mp.mpf(edge)
        W2, H2 = W * W, H * H
        S = mp.sqrt(W2 + H2)
        log_term = (
            mp.log((1 + W2) * (1 + H2) / (1 + W2 + H2))
            + W2 * mp.log(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2)))
            + H2 * mp.log(H2 * (1 + H2 + W2) / ((1 + H2) * (H2 + W2)))
        )
        bracket = W * mp.atan(1 / W) + H * mp.atan(1 / H) - S * mp.atan(1 / S) + log_term / 4
        return _f(bracket / (mp.pi * W))


def coaxial_disks(r1, r2, a):
    """C-41: disk of radius r1 to a parallel coaxial disk of radius r2 at distance a (fronts facing).

    R1 = r1/a, R2 = r2/a, X = 1 + (1 + R2^2) / R1^2,
    F(1 -> 2) = (1/2) (X - sqrt(X^2 - 4 (R2/R1)^2))
              = 2 (R2/R1)^2 / (X + sqrt(X^2 - 4 (R2/R1)^2))   (cancellation-free form used here).

    Source: Howell catalogue C-41; S&H 4th ed. p. 845 via EES f3d_3 (hs203), example r1 = 0.1, r2 = 0.2,
    a = 0.5 -> 0.1339; the same X form on the MayaHTT parallel-disk page (Rohsenow, Handbook of Heat
    Transfer, 3rd ed., p. 7.82).
    """
    with mp.workdps(_DPS):
        R1, R2 = mp.mpf(r1) / mp.mpf(a), mp.mpf(r2) / mp.mpf(a)
        X = 1 + (1 + R2 * R2) / (R1 * R1)
        q = (R2 / R1) ** 2
        return _f(2 * q / (X + mp.sqrt(X * X - 4 * q)))


def disk_to_coaxial_annulus(r1, r_in, r_out, a):
    """Disk r1 to a parallel coaxial annulus r_in..r_out at distance a: C-41(r_out) - C-41(r_in).

    Configuration algebra on `coaxial_disks` (Howell catalogue C-41).
    """
    return coaxial_disks(r1, r_out, a) - coaxial_disks(r1, r_in, a)


# ============================================================================== cylinder inside


def cylinder_end_to_end(r, h):
    """Inside of a closed right circular cylinder (radius r, height h): one end disk to the other.

    C-41 with r1 = r2 = r, a = h (`coaxial_disks`).
    """
    return coaxial_disks(r, r, h)


def cylinder_end_to_lateral(r, h):
    """C-79: base of a right circular cylinder to its inside lateral surface.

    H = h / (2 r),  F = 2 H (sqrt(1 + H^2) - H).

    Source: Howell catalogue C-79, as transcribed in public code (Mirko Vukovic, radiation library,
    inner-cylinder-surfaces-view-factors.lisp, citing www.engr.uky.edu/rtl/Catalog/sectionc/C-79.html);
    EES hs307 (FDiff_7, Howell B-93) example r = 1, h = 2 -> base to inside 0.8284. Equals
    1 - C-41(r, r, h) by summation (checked in the tests).
    """
    with mp.workdps(_DPS):
        H = mp.mpf(h) / (2 * mp.mpf(r))
        return _f(2 * H / (mp.sqrt(1 + H * H) + H))  # = 2H (sqrt(1+H^2) - H)


def cylinder_lateral_to_end(r, h):
    """Inside lateral surface of a right circular cylinder to one end disk: reciprocity on C-79.

    F = (pi r^2) / (2 pi r h) * C-79 = r / (2 h) * cylinder_end_to_lateral(r, h).
    EES hs312 (FDiff_12, Howell B-53) example r = 1, h = 0.5 -> 0.390.
    """
    return r / (2.0 * h) * cylinder_end_to_lateral(r, h)


def cylinder_lateral_self(r, h):
    """C-78: inside lateral surface of a right circular cylinder to itself.

    H = h / (2 r),  F = 1 + H - sqrt(1 + H^2)  (= 1 - 2 * cylinder_lateral_to_end by summation).

    Source: Howell catalogue C-78 as transcribed in Vukovic's inner-cylinder-surfaces-view-factors.lisp;
    also obtained from the enclosure rule with C-79 (checked in the tests). The lateral surface sees
    itself without any third body in the way, so the unoccluded convention gives the same value.
    """
    with mp.workdps(_DPS):
        H = mp.mpf(h) / (2 * mp.mpf(r))
        return _f(1 + H - mp.sqrt(1 + H * H))


def cylinder_band_to_adjacent_band(r, h1, h2):
    """C-86: inside of a cylinder, band of height h1 to the adjacent band of height h2 (shared circle).

    H1 = h1/r, H2 = h2/r,
    F(1 -> 2) = H2/2 + 1/4 [ sqrt(4 + H1^2) + (H2/H1) sqrt(4 + H2^2) - (1 + H2/H1) sqrt(4 + (H1 + H2)^2) ].

    Source: Howell catalogue C-86 as transcribed in Vukovic's inner-cylinder-surfaces-view-factors.lisp;
    agrees with configuration algebra on C-78 (checked in the tests).
    """
    with mp.workdps(_DPS):
        H1, H2 = mp.mpf(h1) / mp.mpf(r), mp.mpf(h2) / mp.mpf(r)
        q = H2 / H1
        return _f(
            H2 / 2
            + (mp.sqrt(4 + H1 * H1) + q * mp.sqrt(4 + H2 * H2) - (1 + q) * mp.sqrt(4 + (H1 + H2) ** 2)) / 4
        )


def cylinder_band_to_band(r, l1, l2, l3):
    """C-87: inside of a cylinder, band l2 <= z <= l3 to band 0 <= z <= l1 (l1 < l2 < l3).

    L_i = l_i / r, X(L) = L sqrt(4 + L^2),
    F = 1 / (4 (L3 - L2)) [ 2 L1 (L3 - L2) + X(L3 - L1) - X(L2 - L1) - X(L3) + X(L2) ].

    Source: Howell catalogue C-87 as transcribed in Vukovic's inner-cylinder-surfaces-view-factors.lisp;
    agrees with configuration algebra on C-78 (checked in the tests).
    """
    with mp.workdps(_DPS):
        L1, L2, L3 = (mp.mpf(x) / mp.mpf(r) for x in (l1, l2, l3))

        def X(L):
            return L * mp.sqrt(4 + L * L)

        return _f((2 * L1 * (L3 - L2) + X(L3 - L1) - X(L2 - L1) - X(L3) + X(L2)) / (4 * (L3 - L2)))


# ========================================================================== coaxial cylinders


def coaxial_cylinders_outer_to_inner(r1, r2, length):
    """Inside of the outer cylinder (radius r2) to the outside of a coaxial inner one (r1), same length.

    R = r2/r1, H = length/r1, A = H^2 + R^2 - 1, B = H^2 - R^2 + 1,
    F(2 -> 1) = 1/R - 1/(pi R) { acos(B/A) - 1/(2H) [ sqrt((A + 2)^2 - (2R)^2) acos(B / (R A))
                                                      + B asin(1/R) - pi A / 2 ] }.

    Source: S&H appendix, "outer surface of cylinder to inner surface of coaxial cylinder, same
    length" (also in Howell's catalogue), as transcribed in public code (a uom-based Rust crate,
    outer_cylinder_to_inner_cylinder_view_factor); EES hs313 (FDiff_13, which integrates Howell's
    element factor B-57 over the outer cylinder) example r1 = 0.5, r2 = 1, length 2 -> 0.4126.
    The original derivation was not seen. Agrees to 1e-15 with the independent closed form in
    `coaxial_cylinders_inner_to_outer` (checked in the tests). Under the unoccluded convention this is
    exact as well: a ray leaving the convex inner cylinder never meets it again.
    """
    with mp.workdps(_DPS):
        r1, r2, ln = mp.mpf(r1), mp.mpf(r2), mp.mpf(length)
        R, H = r2 / r1, ln / r1
        A, B = H * H + R * R - 1, H * H - R * R + 1
        inner = mp.sqrt((A + 2) ** 2 - 4 * R * R) * mp.acos(B / (R * A)) + B * mp.asin(1 / R) - mp.pi * A / 2
        return _f(1 / R - (mp.acos(B / A) - inner / (2 * H)) / (mp.pi * R))


def coaxial_cylinders_inner_to_outer(r1, r2, length):
    """Outside of the inner cylinder (radius r1) to the inside of a coaxial outer one (r2), same length.

    R1 = r1/length, R2 = r2/length, A = R2 + R1, B = R2 - R1,
    F(1 -> 2) = 1 / (pi R1) [ (R2^2 - R1^2 - 1)/2 acos(R1/R2) + pi R1 - pi A B / 2
                              - 2 R1 atan(sqrt(R2^2 - R1^2))
                              + sqrt((1 + A^2)(1 + B^2)) atan( sqrt((1 + A^2) B / ((1 + B^2) A)) ) ].

    Source: as transcribed, under the catalogue-style title "exterior of right circular cylinder of
    finite length to interior of coaxial outer right circular cylinder", in public code
    (rutvi615/double_pipe_heat_exchanger, vf_cal_6.m); its original source was not seen (Howell's
    reference list credits Alexandrov 1965 only with numerical values for this pair). Equals (r2/r1) times
    `coaxial_cylinders_outer_to_inner` (reciprocity), a non-trivial check of both transcriptions.
    """
    with mp.workdps(_DPS):
        r1, r2, ln = mp.mpf(r1), mp.mpf(r2), mp.mpf(length)
        R1, R2 = r1 / ln, r2 / ln
        A, B = R2 + R1, R2 - R1
        val = (
            (R2 * R2 - R1 * R1 - 1) / 2 * mp.acos(R1 / R2)
            + mp.pi * R1
            - mp.pi * A * B / 2
            - 2 * R1 * mp.atan(mp.sqrt(R2 * R2 - R1 * R1))
            + mp.sqrt((1 + A * A) * (1 + B * B)) * mp.atan(mp.sqrt((1 + A * A) * B / ((1 + B * B) * A)))
        )
        return _f(val / (mp.pi * R1))


# ================================================================================ sphere to sphere


def element_to_sphere(H, theta):
    """B-43: differential planar element to a sphere; H = (distance to centre) / radius > 1, tilt theta.

    theta is the angle between the element normal and the line to the sphere centre.
    - theta <= pi/2 - asin(1/H) (sphere wholly above the element's plane): F = cos(theta) / H^2 (B-39
      for theta = 0);
    - theta >= pi/2 + asin(1/H): F = 0;
    - otherwise (partly visible):
      F = 1/2 - asin( sqrt(H^2 - 1) / (H sin theta) ) / pi
          + [ cos(theta) acos(-sqrt(H^2 - 1) cot theta)
              - sqrt(H^2 - 1) sqrt(1 - H^2 cos^2 theta) ] / (pi H^2).

    Source: Howell catalogue B-39 / B-43 ("arbitrarily oriented differential planar element to a
    sphere"), as transcribed in public code (kanamesasaki, sterad_view_factor, diff_element_to_sphere.rs).
    Continuity at both switch angles and the level-element value (theta = pi/2:
    (atan(1/sqrt(H^2 - 1)) - sqrt(H^2 - 1)/H^2) / pi) are checked in the tests.
    Takes and returns mpmath numbers (use inside mp.workdps) or floats.
    """
    return _element_to_sphere_cos(H, mp.cos(theta))


def _element_to_sphere_cos(H, ct):
    H = mp.mpf(H)
    if ct >= 1 / H:
        return ct / (H * H)
    if ct <= -1 / H:
        return mp.mpf(0)
    st = mp.sqrt(1 - ct * ct)
    Q = mp.sqrt(H * H - 1)
    a1 = min(mp.mpf(1), Q / (H * st))
    a2 = max(mp.mpf(-1), min(mp.mpf(1), -Q * ct / st))
    a3 = max(mp.mpf(0), 1 - H * H * ct * ct)
    return mp.mpf(1) / 2 - mp.asin(a1) / mp.pi + (ct * mp.acos(a2) - Q * mp.sqrt(a3)) / (mp.pi * H * H)


def sphere_to_sphere(r1, r2, s):
    """Sphere of radius r1 to a sphere of radius r2, centres s apart (s > r1 + r2), both outsides.

    No closed form was found in the sources consulted (Juul, "Investigation of approximate methods for
    calculation of the diffuse radiation configuration view factor between two spheres", Lett. Heat Mass
    Transfer 3:513-522 (1976), computes it by numerical integration and shows that the point-source
    approximations fail near contact; EES f3d_22 "small sphere to a large sphere" gives the example
    r1 = 0.1, r2 = 0.2, s = 0.5 -> 0.04174). Derived here instead, rigorously:

    F(1 -> 2) = 1/(4 pi r1^2) integral_{S1} F_{dA1 -> S2} dA1, exactly, because for a point of S1 the
    unoccluded pair rule (both fronts facing) counts exactly the cap of S2 visible from that point and in
    front of its tangent plane, which is what B-43 (`element_to_sphere`) measures; S1 is convex so it
    never hides S2 from itself. With alpha the polar angle on S1 measured from the line of centres,

        h(alpha)^2 = r1^2 + s^2 - 2 r1 s cos(alpha),  cos(theta) = (s cos(alpha) - r1) / h,  H = h / r2,
        F(1 -> 2) = 1/2 integral_0^pi F_B43(H(alpha), theta(alpha)) sin(alpha) dalpha.

    The integrand switches formula at cos(alpha) = (r1 + r2)/s (full -> partial) and vanishes beyond
    cos(alpha) = (r1 - r2)/s; mpmath.quad (tanh-sinh) integrates each smooth piece at 40 digits, to a
    relative accuracy better than 1e-15. Reciprocity A1 F12 = A2 F21 (a non-trivial check of the
    derivation), the point-source limit r1 -> 0 (F -> (1 - sqrt(1 - (r2/s)^2)) / 2) and the EES example
    are checked in the tests. Valid for any gap, including nearly touching spheres.
    """
    with mp.workdps(_DPS):
        r1, r2, s = mp.mpf(r1), mp.mpf(r2), mp.mpf(s)

        def integrand(alpha):
            ca = mp.cos(alpha)
            h = mp.sqrt(r1 * r1 + s * s - 2 * r1 * s * ca)
            return _element_to_sphere_cos(h / r2, (s * ca - r1) / h) * mp.sin(alpha)

        a_full = mp.acos((r1 + r2) / s)
        a_zero = mp.acos((r1 - r2) / s)
        # the full-view part has a closed form; integrate both parts numerically (same for both)
        total = mp.quad(integrand, [0, a_full]) + mp.quad(integrand, [a_full, a_zero])
        return _f(total / 2)


# ============================================================================= spheres inside


def sphere_inside_patch(R, u, v):
    """Inside of a sphere of radius R: any patch to the patch {u0 < polar < u1, v0 < azimuth < v1}.

    For two points on the inside of a sphere, cos1 = cos2 = L / (2R), so the kernel
    cos1 cos2 / (pi L^2) = 1 / (4 pi R^2) is constant and F(i -> j) = A_j / (4 pi R^2) for every pair of
    patches, adjacent ones and a patch to itself included.
    Source: S&H, "radiation within a spherical enclosure" (classic result; also the basis of the sphere
    enclosure cases in Howell's catalogue). A_j = R^2 (cos u0 - cos u1)(v1 - v0).
    """
    (u0, u1), (v0, v1) = u, v
    with mp.workdps(_DPS):
        return _f((mp.cos(u0) - mp.cos(u1)) * (mp.mpf(v1) - mp.mpf(v0)) / (4 * mp.pi))


def concentric_spheres(r1, r2):
    """Concentric spheres r1 < r2: returns (F_in_out, F_out_in, F_out_out_occluded, F_out_out_unoccluded).

    Inner sphere (outside) -> outer sphere (inside): 1 (summation, F_11 = 0 for a convex surface).
    Outer (inside) -> inner: (r1/r2)^2 (reciprocity).
    Outer (inside) -> itself: 1 - (r1/r2)^2 in the usual enclosure sense, where the inner sphere hides
    part of the outer one from itself (S&H; engdatabase "concentric spheres" table).
    Under this project's convention (no occlusion by third bodies) the outer sphere's self factor is
    instead 1: every chord of a sphere joins two points facing each other (`sphere_inside_patch`).
    """
    q = (r1 / r2) ** 2
    return 1.0, q, 1.0 - q, 1.0


def ellipsoid_area(a, b, c):
    """Surface area of the ellipsoid with semi-axes a, b, c (Legendre's formula).

    With a >= b >= c, cos(phi) = c/a, m = k^2 = a^2 (b^2 - c^2) / (b^2 (a^2 - c^2)):
    S = 2 pi c^2 + 2 pi a b / sin(phi) * (E(phi, m) sin^2(phi) + F(phi, m) cos^2(phi))
    (DLMF 19.33.2; mpmath ellipe / ellipf, parameter m = k^2). For a = b = c it is 4 pi a^2 (limit).
    """
    a, b, c = sorted((float(a), float(b), float(c)), reverse=True)
    with mp.workdps(_DPS):
        a, b, c = mp.mpf(a), mp.mpf(b), mp.mpf(c)
        if a == c:
            return _f(4 * mp.pi * a * a)
        phi = mp.acos(c / a)
        m = a * a * (b * b - c * c) / (b * b * (a * a - c * c))
        sp, cp = mp.sin(phi), mp.cos(phi)
        return _f(
            2 * mp.pi * c * c
            + 2 * mp.pi * a * b / sp * (mp.ellipe(phi, m) * sp * sp + mp.ellipf(phi, m) * cp * cp)
        )


# ============================================================================ the test cases


@dataclass(frozen=True)
class Case:
    """One configuration: `build()` -> (src, dst) surfaces; `exact` = F(src -> dst).

    Attributes
    ----------
    id : str
    build : callable () -> (Surface, Surface)
    exact : float
    source : str
        Where the value comes from (function of this module and its literature source).
    note : str
        Anything special (near-singular geometry, convention remarks).
    """

    id: str
    build: Callable
    exact: float
    source: str
    note: str = ""


def _rect(x1, x2, y1, y2, z, up=True):
    """Axis-aligned rectangle in the plane z, front +z (up) or -z."""
    p00, p10, p11, p01 = (x1, y1, z), (x2, y1, z), (x2, y2, z), (x1, y2, z)
    if up:
        return core.Quad(p00, p10, p11, p01)
    return core.Quad(p00, p01, p11, p10)


def _rotation(axis, angle):
    """3x3 rotation matrix (Rodrigues)."""
    k = np.asarray(axis, float)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _affine(linear, offset):
    m = np.eye(4)
    m[:3, :3] = linear
    m[:3, 3] = offset
    return m


_ROT = _rotation((1.0, -2.0, 0.5), 0.7)
_RIGID = _affine(_ROT, (0.3, -1.2, 2.5))
# mirror in x, non-uniform scale, then a rotation and a shift
_MIRROR_SCALE = _affine(_ROT @ np.diag((-2.0, 3.0, 0.5)), (-0.4, 0.9, 1.1))

_SEED_SOURCE = (
    "sphere_above_square_centre: four corner rectangles of sphere_to_rectangle_corner "
    "(EES f3d_7 / Tripp, Hwang & Crank 1962 in Howell 1982 p. 190; Howell C-121/C-124, F&G 1970)"
)


def _seed(r):
    return lambda: (core.Sphere((0.0, 0.0, 6.0), r), _rect(-3.0, 3.0, -3.0, 3.0, 0.0))


def _sphere_in_cube():
    return core.Sphere((0.0, 0.0, 0.0), 1.0), _rect(-6.0, 6.0, -6.0, 6.0, -6.0, up=True)


def _c14(w, edge, h):
    """A1: y in [0, w] in the plane z = 0 (front +z); A2: z in [0, h] in the plane y = 0 (front +y)."""
    a1 = core.Quad((0.0, 0.0, 0.0), (edge, 0.0, 0.0), (edge, w, 0.0), (0.0, w, 0.0))
    a2 = core.Quad((0.0, 0.0, 0.0), (0.0, 0.0, h), (edge, 0.0, h), (edge, 0.0, 0.0))
    return a1, a2


def _cylinder_set(r, h, axis=(0.0, 0.0, 1.0), base=(0.0, 0.0, 0.0)):
    """Inside of a closed cylinder: lateral (flipped), bottom disk and top disk, both facing inwards."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    base = np.asarray(base, float)
    lateral = core.Cylinder(base, axis, r, h).flipped()
    bottom = core.Disk(base, axis, r)
    top = core.Disk(base + h * axis, -axis, r)
    return lateral, bottom, top


def _hemisphere():
    hemi = core.Sphere((0.0, 0.0, 0.0), 1.0).flipped().subpatch(u=(0.0, np.pi / 2))
    base = core.Disk((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0)
    return hemi, base


_SPHERE_INSIDE_R = 1.5


def _sphere_inside():
    sphere = core.Sphere((0.3, -0.2, 0.1), _SPHERE_INSIDE_R)
    return sphere.transformed(_affine(_ROT, (0.0, 0.0, 0.0))).flipped()


_P1 = dict(u=(0.4, 1.3), v=(0.2, 1.7))
_P2 = dict(u=(0.4, 1.3), v=(1.7, 3.0))
_P3 = dict(u=(2.0, np.pi), v=(0.0, 2.0 * np.pi))


def _ellipsoid():
    m = _affine(_ROT @ np.diag((1.0, 0.6, 0.4)), (0.2, 0.1, -0.1))
    return core.Sphere((0.0, 0.0, 0.0), 1.0).transformed(m)


def _make_cases():
    cases = []

    def add(id_, build, exact, source, note=""):
        cases.append(Case(id_, build, float(exact), source, note))

    # ---------------------------------------------------------------- seed cases
    for r, tag in ((1.0, "r1"), (1e-3, "r1e-3"), (1e-6, "r1e-6")):
        add(
            f"seed_sphere_{tag}_above_square",
            _seed(r),
            sphere_above_square_centre(6.0, 6.0),
            _SEED_SOURCE,
            "sphere centre 6 above the centre of a 6 x 6 square; exact = atan(1/sqrt(24))/pi = "
            "0.0640942168489749 for any r < 6",
        )
    add(
        "sphere_in_cube_to_face",
        _sphere_in_cube,
        sphere_to_rectangle(-6.0, 6.0, -6.0, 6.0, 6.0),
        "sphere_to_rectangle (superposition, Howell C-124) = 1/6 by symmetry of the six faces",
        "sphere r = 1 at the centre of a cube of side 12, to one face",
    )
    add(
        "cube_face_to_sphere_inside",
        lambda: _sphere_in_cube()[::-1],
        4.0 * np.pi / 144.0 / 6.0,
        "reciprocity on sphere_in_cube_to_face: (4 pi / 144) * (1/6) = pi / 216",
    )

    # ---------------------------------------------------------------- sphere to flat shapes
    add(
        "sphere_to_rectangle_corner",
        lambda: (core.Sphere((0.0, 0.0, 1.5), 0.5), _rect(0.0, 2.0, 0.0, 3.0, 0.0)),
        sphere_to_rectangle_corner(2.0, 3.0, 1.5),
        "sphere_to_rectangle_corner (EES f3d_7; Tripp, Hwang & Crank 1962 in Howell 1982 p. 190)",
        "sphere centre on the normal through a corner of a 2 x 3 rectangle",
    )
    add(
        "sphere_to_rectangle_offset",
        lambda: (core.Sphere((0.0, 0.0, 1.2), 1.0), _rect(1.0, 3.0, -0.5, 2.0, 0.0)),
        sphere_to_rectangle(1.0, 3.0, -0.5, 2.0, 1.2),
        "sphere_to_rectangle: superposition of four corner factors (Howell C-124, F&G 1970)",
        "rectangle offset from the axis and straddling one coordinate plane; sphere radius close to d",
    )
    add(
        "sphere_to_triangle",
        lambda: (
            core.Sphere((0.0, 0.0, 1.0), 0.5),
            core.Quad((0.0, 0.0, 0.0), (2.0, 0.0, 0.0), (2.0, 1.5, 0.0), (0.0, 0.0, 0.0)),
        ),
        sphere_to_triangle((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (2.0, 0.0, 0.0), (2.0, 1.5, 0.0)),
        "sphere_to_triangle: solid angle / 4 pi (F&G 1970; Howell C-123/C-124; Van Oosterom & Strackee 1983)",
        "triangle as a Quad with p01 = p00 (collapsed edge)",
    )
    add(
        "sphere_to_coaxial_disk",
        lambda: (core.Sphere((0.0, 0.0, 2.0), 1.0), core.Disk((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 3.0)),
        sphere_to_coaxial_disk(3.0, 2.0),
        "sphere_to_coaxial_disk (EES f3d_16; Rohsenow, Handbook of Heat Transfer 3rd ed. p. 7.84)",
    )
    add(
        "coaxial_disk_to_sphere",
        lambda: (core.Disk((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 3.0), core.Sphere((0.0, 0.0, 2.0), 1.0)),
        disk_to_coaxial_sphere(3.0, 2.0, 1.0),
        "disk_to_coaxial_sphere: reciprocity on sphere_to_coaxial_disk",
    )
    add(
        "sphere_to_coaxial_annulus",
        lambda: (
            core.Sphere((0.0, 0.0, 2.0), 1.0),
            core.Disk((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 3.0).subpatch(u=(1.0, 3.0)),
        ),
        sphere_to_coaxial_annulus(1.0, 3.0, 2.0),
        "sphere_to_coaxial_annulus: difference of two sphere_to_coaxial_disk (EES f3d_16)",
        "annulus as Disk.subpatch(u=(1, 3))",
    )
    add(
        "sphere_to_ellipse_nonuniform_scale",
        lambda: (
            core.Sphere((0.0, 0.0, 1.5), 0.5),
            core.Disk((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0).transformed(np.diag((2.0, 0.7, 1.0, 1.0))),
        ),
        sphere_to_coaxial_ellipse(2.0, 0.7, 1.5),
        "sphere_to_coaxial_ellipse: solid angle / 4 pi (F&G 1970), 1D integral derived here",
        "ellipse = unit disk under the non-uniform scale diag(2, 0.7, 1)",
    )

    # ---------------------------------------------------------------- flat to flat
    add(
        "c11_parallel_rectangles",
        lambda: (_rect(0.0, 2.0, 0.0, 3.0, 0.0), _rect(0.0, 2.0, 0.0, 3.0, 1.0, up=False)),
        parallel_rectangles(2.0, 3.0, 1.0),
        "parallel_rectangles: Howell C-11 (Hottel 1931; Hamilton & Morgan 1952)",
    )
    add(
        "c11_tiny_far_squares",
        lambda: (_rect(0.0, 1e-4, 0.0, 1e-4, 0.0), _rect(0.0, 1e-4, 0.0, 1e-4, 1.0, up=False)),
        parallel_rectangles(1e-4, 1e-4, 1.0),
        "parallel_rectangles: Howell C-11 evaluated at 60 digits",
        "two 1e-4 m squares 1 m apart: F = 3.18309886e-9 (double-precision C-11 would give noise)",
    )
    add(
        "c11_mirrored_nonuniform_rotated",
        lambda: (
            _rect(0.0, 1.0, 0.0, 1.0, 0.0).transformed(_MIRROR_SCALE),
            _rect(0.0, 1.0, 0.0, 1.0, 1.0, up=False).transformed(_MIRROR_SCALE),
        ),
        parallel_rectangles(2.0, 3.0, 0.5),
        "parallel_rectangles: Howell C-11 (image of unit squares 1 apart under diag(-2, 3, 0.5) + rotation)",
        "a mirroring, non-uniformly scaling, rotating transform: fronts must stay facing each other",
    )
    add(
        "c14_perpendicular_rectangles",
        lambda: _c14(1.0, 2.0, 1.5),
        perpendicular_rectangles(1.0, 2.0, 1.5),
        "perpendicular_rectangles: Howell C-14 (Hottel 1931; Hamilton & Morgan 1952)",
        "shared edge of length 2: integrable 1/L^2 singularity along it",
    )
    add(
        "c14_rotated_translated",
        lambda: tuple(s.transformed(_RIGID) for s in _c14(0.5, 1.0, 2.0)),
        perpendicular_rectangles(0.5, 1.0, 2.0),
        "perpendicular_rectangles: Howell C-14 under a rigid motion",
        "shared edge; rotated about (1, -2, 0.5) by 0.7 rad and shifted",
    )
    add(
        "c41_coaxial_disks",
        lambda: (
            core.Disk((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0),
            core.Disk((0.0, 0.0, 1.5), (0.0, 0.0, -1.0), 2.0),
        ),
        coaxial_disks(1.0, 2.0, 1.5),
        "coaxial_disks: Howell C-41 (S&H 4th ed. p. 845 via EES f3d_3)",
    )
    add(
        "c41_disk_to_coaxial_annulus",
        lambda: (
            core.Disk((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0),
            core.Disk((0.0, 0.0, 1.5), (0.0, 0.0, -1.0), 2.0).subpatch(u=(0.5, 2.0)),
        ),
        disk_to_coaxial_annulus(1.0, 0.5, 2.0, 1.5),
        "disk_to_coaxial_annulus: difference of two Howell C-41",
    )

    # ---------------------------------------------------------------- concentric spheres
    f_in_out, f_out_in, _, f_out_out = concentric_spheres(1.0, 2.0)
    add(
        "concentric_inner_to_outer_inside",
        lambda: (core.Sphere((0.0, 0.0, 0.0), 1.0), core.Sphere((0.0, 0.0, 0.0), 2.0).flipped()),
        f_in_out,
        "concentric_spheres: summation rule (S&H)",
    )
    add(
        "concentric_outer_inside_to_inner",
        lambda: (core.Sphere((0.0, 0.0, 0.0), 2.0).flipped(), core.Sphere((0.0, 0.0, 0.0), 1.0)),
        f_out_in,
        "concentric_spheres: reciprocity, (r1/r2)^2 (S&H)",
    )
    add(
        "concentric_outer_inside_self_unoccluded",
        lambda: (core.Sphere((0.0, 0.0, 0.0), 2.0).flipped(),) * 2,
        f_out_out,
        "sphere_inside_patch (whole sphere: 1); NOT the enclosure value 1 - (r1/r2)^2 = 0.75",
        "the inner sphere is a third body, which this convention does not let occlude",
    )

    # ---------------------------------------------------------------- hemisphere and base
    add(
        "hemisphere_inside_self",
        lambda: (_hemisphere()[0],) * 2,
        0.5,
        "sphere_inside_patch: A_hemi / (4 pi R^2) = 1/2 (S&H); also 1 - F(hemi -> base)",
    )
    add(
        "hemisphere_inside_to_base",
        _hemisphere,
        0.5,
        "enclosure {hemisphere, base}: F(base -> hemi) = 1, reciprocity (pi R^2)/(2 pi R^2) = 1/2",
    )
    add(
        "base_to_hemisphere_inside",
        lambda: _hemisphere()[::-1],
        1.0,
        "summation rule: a flat disk (F_bb = 0) closed by the hemisphere (S&H)",
    )

    # ---------------------------------------------------------------- inside of a sphere
    R = _SPHERE_INSIDE_R
    add(
        "sphere_inside_patch_to_adjacent_patch",
        lambda: (_sphere_inside().subpatch(**_P1), _sphere_inside().subpatch(**_P2)),
        sphere_inside_patch(R, _P2["u"], _P2["v"]),
        "sphere_inside_patch: A_j / (4 pi R^2) (S&H)",
        "patches share the edge v = 1.7; sphere rotated and shifted",
    )
    add(
        "sphere_inside_patch_to_itself",
        lambda: (_sphere_inside().subpatch(**_P1),) * 2,
        sphere_inside_patch(R, _P1["u"], _P1["v"]),
        "sphere_inside_patch: A_i / (4 pi R^2) (S&H)",
    )
    add(
        "sphere_inside_patch_to_polar_cap",
        lambda: (_sphere_inside().subpatch(**_P1), _sphere_inside().subpatch(**_P3)),
        sphere_inside_patch(R, _P3["u"], _P3["v"]),
        "sphere_inside_patch: A_j / (4 pi R^2) (S&H)",
        "destination is a cap around the parametric pole u = pi",
    )
    add(
        "sphere_inside_corner_neighbours",
        lambda: (lambda p: (p[5], p[10]))(_sphere_inside().split(3, 4)),
        sphere_inside_patch(R, (2 * np.pi / 3, np.pi), (np.pi, 1.5 * np.pi)),
        "sphere_inside_patch: A_j / (4 pi R^2) (S&H)",
        "split(3, 4) cells 5 and 10 touch at one corner only",
    )
    add(
        "sphere_inside_self",
        lambda: (_sphere_inside(),) * 2,
        1.0,
        "sphere_inside_patch with the whole sphere: 1",
    )

    # ---------------------------------------------------------------- cylinder inside
    cr, ch = 1.0, 2.0
    tilt = (1.0, 1.0, 1.0)
    add(
        "cylinder_lateral_to_end",
        lambda: _cylinder_set(cr, ch)[:2],
        cylinder_lateral_to_end(cr, ch),
        "cylinder_lateral_to_end: reciprocity on Howell C-79",
    )
    add(
        "cylinder_end_to_lateral",
        lambda: _cylinder_set(cr, ch, axis=tilt, base=(1.0, 0.0, -1.0))[1::-1],
        cylinder_end_to_lateral(cr, ch),
        "cylinder_end_to_lateral: Howell C-79 (EES hs307 / B-93 example 0.8284)",
        "cylinder axis along (1, 1, 1)",
    )
    add(
        "cylinder_end_to_end",
        lambda: _cylinder_set(cr, ch)[1:],
        cylinder_end_to_end(cr, ch),
        "cylinder_end_to_end: Howell C-41 with equal radii",
    )
    add(
        "cylinder_lateral_self",
        lambda: (_cylinder_set(cr, ch, axis=tilt)[0],) * 2,
        cylinder_lateral_self(cr, ch),
        "cylinder_lateral_self: Howell C-78 = 1 - 2 F(lateral -> end) (enclosure rule)",
        "cylinder axis along (1, 1, 1)",
    )
    add(
        "cylinder_band_to_adjacent_band",
        lambda: (
            _cylinder_set(cr, ch)[0].subpatch(v=(0.0, 0.8)),
            _cylinder_set(cr, ch)[0].subpatch(v=(0.8, 2.0)),
        ),
        cylinder_band_to_adjacent_band(cr, 0.8, 1.2),
        "cylinder_band_to_adjacent_band: Howell C-86",
        "bands share the circle z = 0.8",
    )
    add(
        "cylinder_band_to_distant_band",
        lambda: (
            _cylinder_set(cr, ch)[0].subpatch(v=(1.2, 2.0)),
            _cylinder_set(cr, ch)[0].subpatch(v=(0.0, 0.5)),
        ),
        cylinder_band_to_band(cr, 0.5, 1.2, 2.0),
        "cylinder_band_to_band: Howell C-87",
    )
    add(
        "coaxial_cylinders_inner_to_outer",
        lambda: (
            core.Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.5, 2.0),
            core.Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0, 2.0).flipped(),
        ),
        coaxial_cylinders_inner_to_outer(0.5, 1.0, 2.0),
        "coaxial_cylinders_inner_to_outer: closed form as in vf_cal_6.m; = (r2/r1) x S&H outer-to-inner form",
        "EES hs313 example: outer -> inner 0.4126, so inner -> outer 0.8252",
    )
    add(
        "coaxial_cylinders_outer_to_inner",
        lambda: (
            core.Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0, 2.0).flipped(),
            core.Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.5, 2.0),
        ),
        coaxial_cylinders_outer_to_inner(0.5, 1.0, 2.0),
        "coaxial_cylinders_outer_to_inner: S&H (Howell catalogue; EES hs313/B-57 example 0.4126)",
    )

    # ---------------------------------------------------------------- sphere to sphere
    add(
        "sphere_to_sphere_equal_3R",
        lambda: (core.Sphere((0.0, 0.0, 0.0), 1.0), core.Sphere((0.0, 0.0, 3.0), 1.0)),
        sphere_to_sphere(1.0, 1.0, 3.0),
        "sphere_to_sphere: integral of Howell B-43 over the first sphere (derived here; cf. Juul 1976)",
    )
    add(
        "sphere_to_sphere_gap_1e-3",
        lambda: (core.Sphere((0.0, 0.0, 0.0), 1.0), core.Sphere((0.0, 0.0, 2.001), 1.0)),
        sphere_to_sphere(1.0, 1.0, 2.001),
        "sphere_to_sphere: integral of Howell B-43 over the first sphere (derived here; cf. Juul 1976)",
        "nearly touching: gap 1e-3 R, kernel peak ~1e6 in a spot of radius ~0.03 R at the poles",
    )
    add(
        "sphere_to_sphere_unequal",
        lambda: (
            core.Sphere((0.1, 0.2, 0.3), 0.1),
            core.Sphere(np.array((0.1, 0.2, 0.3)) + 0.5 * np.array((0.6, 0.0, 0.8)), 0.2),
        ),
        sphere_to_sphere(0.1, 0.2, 0.5),
        "sphere_to_sphere (derived here); EES f3d_22 example r1 = 0.1, r2 = 0.2, s = 0.5 -> 0.04174",
        "line of centres oblique to the parametrisation axis",
    )
    add(
        "sphere_to_sphere_unequal_reverse",
        lambda: (
            core.Sphere(np.array((0.1, 0.2, 0.3)) + 0.5 * np.array((0.6, 0.0, 0.8)), 0.2),
            core.Sphere((0.1, 0.2, 0.3), 0.1),
        ),
        sphere_to_sphere(0.2, 0.1, 0.5),
        "sphere_to_sphere (derived here); reciprocity with sphere_to_sphere_unequal",
    )

    # ---------------------------------------------------------------- ellipsoid in a sphere
    area_e = ellipsoid_area(1.0, 0.6, 0.4)
    add(
        "ellipsoid_to_enclosing_sphere",
        lambda: (_ellipsoid(), core.Sphere((0.0, 0.0, 0.0), 2.0).flipped()),
        1.0,
        "summation rule: a convex body (F_11 = 0) inside an enclosure (S&H)",
        "ellipsoid = unit sphere under diag(1, 0.6, 0.4) + rotation + shift",
    )
    add(
        "enclosing_sphere_to_ellipsoid",
        lambda: (core.Sphere((0.0, 0.0, 0.0), 2.0).flipped(), _ellipsoid()),
        area_e / (16.0 * np.pi),
        "reciprocity on ellipsoid_to_enclosing_sphere; ellipsoid_area by Legendre's formula (DLMF 19.33.2)",
    )
    return cases


CASES = _make_cases()


def case(id_):
    """The case with this id."""
    for c in CASES:
        if c.id == id_:
            return c
    raise KeyError(id_)
