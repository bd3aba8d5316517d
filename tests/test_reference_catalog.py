"""Quick checks of the reference view-factor catalogue (tests/reference/view_factors.py) against itself.

Formulas are played against each other (reciprocity, summation over enclosures, configuration algebra,
limiting cases, independent transcriptions of the same factor) and against the worked numerical
examples printed in the sources. The slow brute-force check of every case is
tests/reference/check_catalog.py.
"""

import math
import pathlib
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import core  # noqa: E402
from tests.reference import view_factors as vf  # noqa: E402


def rel(a, b):
    return abs(a - b) / max(abs(a), abs(b))


# ------------------------------------------------------------------ the seed value and sphere-to-plane


def test_seed_value():
    f = vf.sphere_above_square_centre(6.0, 6.0)
    assert f == pytest.approx(0.0640942168489749, rel=1e-15)
    assert f == pytest.approx(math.atan(1.0 / math.sqrt(24.0)) / math.pi, rel=1e-15)
    assert f == pytest.approx(vf.sphere_to_rectangle(-3.0, 3.0, -3.0, 3.0, 6.0), rel=1e-15)
    seeds = [c for c in vf.CASES if c.id.startswith("seed_")]
    assert len(seeds) == 3 and all(c.exact == f for c in seeds)


def test_sphere_in_box_faces_sum_to_one():
    """Sphere anywhere inside a box: the six faces (superposed corner factors) see all of it."""
    a, b, c = 3.0, 4.0, 5.0
    x, y, z = 0.7, 2.9, 1.3
    faces = [
        vf.sphere_to_rectangle(-x, a - x, -y, b - y, z),  # bottom
        vf.sphere_to_rectangle(-x, a - x, -y, b - y, c - z),  # top
        vf.sphere_to_rectangle(-y, b - y, -z, c - z, x),  # x = 0
        vf.sphere_to_rectangle(-y, b - y, -z, c - z, a - x),  # x = a
        vf.sphere_to_rectangle(-x, a - x, -z, c - z, y),  # y = 0
        vf.sphere_to_rectangle(-x, a - x, -z, c - z, b - y),  # y = b
    ]
    assert sum(faces) == pytest.approx(1.0, rel=1e-14)
    assert vf.sphere_to_rectangle(-6.0, 6.0, -6.0, 6.0, 6.0) == pytest.approx(1.0 / 6.0, rel=1e-15)


def test_sphere_to_rectangle_literature_example():
    # EES f3d_7 (Tripp, Hwang & Crank, in Howell 1982 p. 190): l1 = l2 = d = 0.5 -> 0.04167
    assert vf.sphere_to_rectangle_corner(0.5, 0.5, 0.5) == pytest.approx(0.04167, abs=5e-6)
    assert vf.sphere_to_rectangle_corner(0.5, 0.5, 0.5) == pytest.approx(1.0 / 24.0, rel=1e-15)
    # symmetric in the two sides, zero for a degenerate rectangle
    assert vf.sphere_to_rectangle_corner(2.0, 3.0, 1.5) == vf.sphere_to_rectangle_corner(3.0, 2.0, 1.5)
    assert vf.sphere_to_rectangle_corner(0.0, 3.0, 1.5) == 0.0


def test_far_rectangle_point_source_limit():
    # small rectangle (area A) far below the sphere centre: F -> A cos / (4 pi d^2)
    d, s = 10.0, 1e-3
    assert vf.sphere_to_rectangle(-s, s, -s, s, d) == pytest.approx(
        4 * s * s / (4 * math.pi * d * d), rel=1e-7
    )


def test_triangles_add_up_to_rectangle():
    centre = (0.3, -0.4, 1.7)
    corners = [(-1.0, -0.5, 0.0), (2.0, -0.5, 0.0), (2.0, 1.5, 0.0), (-1.0, 1.5, 0.0)]
    shifted = [(px - centre[0], py - centre[1]) for px, py, _ in corners]
    rect = vf.sphere_to_rectangle(shifted[0][0], shifted[1][0], shifted[0][1], shifted[2][1], centre[2])
    tri = vf.sphere_to_triangle(centre, corners[0], corners[1], corners[2]) + vf.sphere_to_triangle(
        centre, corners[0], corners[2], corners[3]
    )
    assert tri == pytest.approx(rect, rel=1e-14)


def test_sphere_to_disk_literature_and_limits():
    # EES f3d_16 (Rohsenow, Handbook of Heat Transfer, p. 7.84): R = 1, h = 0.5 -> 0.2764
    assert vf.sphere_to_coaxial_disk(1.0, 0.5) == pytest.approx(0.2764, abs=5e-5)
    # far disk: F = x^2/4 - 3 x^4/16 + O(x^6), x = R/h, i.e. A_disk / (4 pi h^2) to leading order
    for x in (1e-2, 1e-3, 1e-5):
        expected = x * x / 4 - 3 * x**4 / 16
        assert vf.sphere_to_coaxial_disk(x, 1.0) == pytest.approx(expected, rel=max(1e-14, 2 * x**4))
    # infinite plane: one half of the sphere
    assert vf.sphere_to_coaxial_disk(1e9, 1.0) == pytest.approx(0.5, rel=1e-9)
    # annulus = difference, disk-to-sphere = reciprocity
    assert vf.sphere_to_coaxial_annulus(1.0, 3.0, 2.0) == pytest.approx(
        vf.sphere_to_coaxial_disk(3.0, 2.0) - vf.sphere_to_coaxial_disk(1.0, 2.0), rel=1e-15
    )
    R, h, r = 3.0, 2.0, 1.0
    assert math.pi * R * R * vf.disk_to_coaxial_sphere(R, h, r) == pytest.approx(
        4 * math.pi * r * r * vf.sphere_to_coaxial_disk(R, h), rel=1e-15
    )


def test_ellipse_reduces_to_disk_and_is_symmetric():
    assert vf.sphere_to_coaxial_ellipse(1.3, 1.3, 0.8) == pytest.approx(
        vf.sphere_to_coaxial_disk(1.3, 0.8), rel=1e-14
    )
    assert vf.sphere_to_coaxial_ellipse(2.0, 0.7, 1.5) == pytest.approx(
        vf.sphere_to_coaxial_ellipse(0.7, 2.0, 1.5), rel=1e-14
    )
    # between the inscribed and circumscribed disks
    f = vf.sphere_to_coaxial_ellipse(2.0, 0.7, 1.5)
    assert vf.sphere_to_coaxial_disk(0.7, 1.5) < f < vf.sphere_to_coaxial_disk(2.0, 1.5)


# ------------------------------------------------------------------------------ flat to flat


def test_box_faces_sum_to_one():
    """C-11 + 2 x C-14 + 2 x C-14 = 1 from a face of any rectangular box."""
    for a, b, c in ((1.0, 1.0, 1.0), (2.0, 3.0, 0.5), (0.3, 5.0, 2.0)):
        total = (
            vf.parallel_rectangles(a, b, c)
            + 2 * vf.perpendicular_rectangles(b, a, c)
            + 2 * vf.perpendicular_rectangles(a, b, c)
        )
        assert total == pytest.approx(1.0, rel=1e-14)
    assert vf.perpendicular_rectangles(1.0, 1.0, 1.0) == pytest.approx(0.2000438, abs=1e-7)


def test_c11_literature_and_small_limit():
    # EES f3d_1 (S&H 4th ed. p. 843): a = 1, b = 1.5, c = 0.5 -> 0.4756
    assert vf.parallel_rectangles(1.0, 1.5, 0.5) == pytest.approx(0.4756, abs=5e-5)
    assert vf.parallel_rectangles(2.0, 3.0, 1.0) == pytest.approx(
        vf.parallel_rectangles(3.0, 2.0, 1.0), rel=1e-15
    )
    # tiny far squares: F = A / (pi c^2) (1 - O(X^2)); double-precision C-11 would be noise here
    f = vf.parallel_rectangles(1e-4, 1e-4, 1.0)
    assert f == pytest.approx(1e-8 / math.pi, rel=1e-7)
    assert f < 1e-8 / math.pi


def test_c14_reciprocity():
    for w, edge, h in ((1.0, 2.0, 1.5), (0.5, 1.0, 2.0), (3.0, 0.2, 0.7)):
        assert w * vf.perpendicular_rectangles(w, edge, h) == pytest.approx(
            h * vf.perpendicular_rectangles(h, edge, w), rel=1e-14
        )


def test_c41_literature_reciprocity_and_limits():
    # EES f3d_3 (S&H 4th ed. p. 845): r1 = 0.1, r2 = 0.2, a = 0.5 -> 0.1339
    assert vf.coaxial_disks(0.1, 0.2, 0.5) == pytest.approx(0.1339, abs=5e-5)
    for r1, r2, a in ((1.0, 2.0, 1.5), (0.3, 0.1, 2.0), (1.0, 1.0, 1e-3)):
        assert r1 * r1 * vf.coaxial_disks(r1, r2, a) == pytest.approx(
            r2 * r2 * vf.coaxial_disks(r2, r1, a), rel=1e-13
        )
    # tiny disk facing a large one: the element-to-disk factor R^2 / (R^2 + a^2) (Howell B-12)
    assert vf.coaxial_disks(1e-6, 2.0, 1.5) == pytest.approx(4.0 / (4.0 + 2.25), rel=1e-10)
    assert vf.disk_to_coaxial_annulus(1.0, 0.5, 2.0, 1.5) == pytest.approx(
        vf.coaxial_disks(1.0, 2.0, 1.5) - vf.coaxial_disks(1.0, 0.5, 1.5), rel=1e-15
    )


# ------------------------------------------------------------------------------ cylinders


@pytest.mark.parametrize("r, h", [(1.0, 2.0), (1.0, 0.5), (0.3, 7.0)])
def test_cylinder_enclosure_rules(r, h):
    end_lat = vf.cylinder_end_to_lateral(r, h)
    assert end_lat == pytest.approx(1.0 - vf.cylinder_end_to_end(r, h), rel=1e-13)  # C-79 vs C-41
    lat_end = vf.cylinder_lateral_to_end(r, h)
    assert 2 * math.pi * r * h * lat_end == pytest.approx(math.pi * r * r * end_lat, rel=1e-14)
    assert vf.cylinder_lateral_self(r, h) == pytest.approx(1.0 - 2.0 * lat_end, rel=1e-13)  # C-78


def test_cylinder_literature_examples():
    # EES hs307 (Howell B-93): r = 1, h = 2, base to inside 0.8284 (0.8285 by their integration)
    assert vf.cylinder_end_to_lateral(1.0, 2.0) == pytest.approx(0.8284, abs=5e-5)
    # EES hs312 (Howell B-53): r = 1, h = 0.5, inside to base 0.390
    assert vf.cylinder_lateral_to_end(1.0, 0.5) == pytest.approx(0.390, abs=5e-4)


@pytest.mark.parametrize("r, h1, h2", [(1.0, 0.8, 1.2), (0.5, 2.0, 0.3), (2.0, 1.0, 1.0)])
def test_cylinder_bands_by_algebra(r, h1, h2):
    """C-86 and C-87 against C-78 self factors of bands (configuration algebra)."""

    def self_(h):
        return vf.cylinder_lateral_self(r, h)

    # A_T F_TT = A1 F11 + A2 F22 + 2 A1 F12 (areas proportional to heights)
    f12 = ((h1 + h2) * self_(h1 + h2) - h1 * self_(h1) - h2 * self_(h2)) / (2 * h1)
    assert vf.cylinder_band_to_adjacent_band(r, h1, h2) == pytest.approx(f12, rel=1e-12)
    # C-87: band [l2, l3] to band [0, l1] = C-86 to [0, l2] minus C-86 to the gap [l1, l2]
    l1, l2, l3 = h1, h1 + 0.4, h1 + 0.4 + h2
    via_86 = vf.cylinder_band_to_adjacent_band(r, l3 - l2, l2) - vf.cylinder_band_to_adjacent_band(
        r, l3 - l2, l2 - l1
    )
    assert vf.cylinder_band_to_band(r, l1, l2, l3) == pytest.approx(via_86, rel=1e-12)


@pytest.mark.parametrize(
    "r1, r2, length", [(0.5, 1.0, 2.0), (0.2, 1.0, 0.5), (0.9, 1.0, 10.0), (1.0, 3.0, 1.0)]
)
def test_coaxial_cylinder_transcriptions_agree(r1, r2, length):
    """Two independent closed forms (S&H form, and Howell's inner-to-outer form) related by reciprocity."""
    inner_to_outer = vf.coaxial_cylinders_inner_to_outer(r1, r2, length)
    outer_to_inner = vf.coaxial_cylinders_outer_to_inner(r1, r2, length)
    assert inner_to_outer == pytest.approx(r2 / r1 * outer_to_inner, rel=1e-13)
    assert 0.0 < inner_to_outer < 1.0


def test_coaxial_cylinders_literature_and_limits():
    # EES hs313 (Howell B-57): r1 = 0.5, r2 = 1, h = 2: outer -> inner 0.4126
    assert vf.coaxial_cylinders_outer_to_inner(0.5, 1.0, 2.0) == pytest.approx(0.4126, abs=5e-5)
    # very long cylinders: the inner one sees only the outer one
    assert vf.coaxial_cylinders_inner_to_outer(0.5, 1.0, 1e4) == pytest.approx(1.0, abs=1e-4)


# --------------------------------------------------------------------------------- spheres


def test_element_to_sphere_pieces_join():
    import mpmath as mp

    with mp.workdps(30):
        for H in (mp.mpf("1.001"), mp.mpf("1.5"), mp.mpf(3), mp.mpf(40)):
            phi = mp.asin(1 / H)
            for edge in (mp.pi / 2 - phi, mp.pi / 2 + phi):
                lo = vf.element_to_sphere(H, edge - mp.mpf("1e-20"))
                hi = vf.element_to_sphere(H, edge + mp.mpf("1e-20"))
                assert abs(lo - hi) < 1e-15
            level = vf.element_to_sphere(H, mp.pi / 2)
            q = mp.sqrt(H * H - 1)
            assert abs(level - (mp.atan(1 / q) - q / H**2) / mp.pi) < 1e-25
            assert abs(vf.element_to_sphere(H, 0) - 1 / H**2) < 1e-25  # B-39


@pytest.mark.parametrize("r1, r2, s", [(1.0, 1.0, 3.0), (0.1, 0.2, 0.5), (1.0, 0.3, 1.5), (1.0, 1.0, 2.001)])
def test_sphere_to_sphere_reciprocity(r1, r2, s):
    f12, f21 = vf.sphere_to_sphere(r1, r2, s), vf.sphere_to_sphere(r2, r1, s)
    assert r1 * r1 * f12 == pytest.approx(r2 * r2 * f21, rel=1e-13)


def test_sphere_to_sphere_limits():
    # tiny emitter: the solid angle of the far sphere over 4 pi
    r2, s = 1.0, 3.0
    point = (1 - math.sqrt(1 - (r2 / s) ** 2)) / 2
    assert vf.sphere_to_sphere(1e-4, r2, s) == pytest.approx(point, rel=1e-7)
    # far apart: F -> (r2 / s)^2 / 4
    assert vf.sphere_to_sphere(1.0, 1.0, 1e3) == pytest.approx(0.25e-6, rel=1e-5)
    # closing the gap, F grows monotonically towards the touching value
    gaps = [vf.sphere_to_sphere(1.0, 1.0, 2.0 + g) for g in (1.0, 0.1, 1e-2, 1e-3, 1e-5)]
    assert all(a < b for a, b in zip(gaps, gaps[1:]))


def test_sphere_to_sphere_vs_ees_point_source():
    """Documented discrepancy: EES f3d_22's example (0.04174) is the spherical point-source value.

    For r1 = 0.1, r2 = 0.2, s = 0.5, (1 - sqrt(1 - (r2/s)^2)) / 2 = 0.041742 reproduces EES's 0.04174,
    while the exact factor (integral of B-43, confirmed by the brute-force check) is 0.042278,
    1.3 % higher (Juul 1976 discusses the error of such approximations).
    """
    point = (1 - math.sqrt(1 - 0.4**2)) / 2
    assert point == pytest.approx(0.04174, abs=5e-6)
    assert vf.sphere_to_sphere(0.1, 0.2, 0.5) == pytest.approx(0.0422780, abs=1e-7)


def test_sphere_inside_patches_sum_to_one():
    R = 1.7
    total = 0.0
    us, vs = np.linspace(0, np.pi, 4), np.linspace(0, 2 * np.pi, 6)
    for u in zip(us, us[1:]):
        for v in zip(vs, vs[1:]):
            total += vf.sphere_inside_patch(R, u, v)
    assert total == pytest.approx(1.0, rel=1e-14)


def test_concentric_spheres():
    f_in_out, f_out_in, f_out_out_occ, f_out_out = vf.concentric_spheres(1.0, 2.0)
    assert f_in_out == 1.0 and f_out_out == 1.0
    assert 4 * math.pi * f_in_out == pytest.approx(16 * math.pi * f_out_in, rel=1e-15)
    assert f_out_in + f_out_out_occ == pytest.approx(1.0, rel=1e-15)


def test_ellipsoid_area():
    assert vf.ellipsoid_area(1.3, 1.3, 1.3) == pytest.approx(4 * math.pi * 1.69, rel=1e-15)
    # oblate spheroid: 2 pi a^2 (1 + (1 - e^2) atanh(e) / e)
    a, c = 1.0, 0.4
    e = math.sqrt(1 - (c / a) ** 2)
    oblate = 2 * math.pi * a * a * (1 + (1 - e * e) * math.atanh(e) / e)
    assert vf.ellipsoid_area(a, a, c) == pytest.approx(oblate, rel=1e-13)
    # prolate spheroid: 2 pi b^2 (1 + a asin(e) / (b e)), b the equatorial radius
    a, b = 1.0, 0.6
    e = math.sqrt(1 - (b / a) ** 2)
    prolate = 2 * math.pi * b * b * (1 + a * math.asin(e) / (b * e))
    assert vf.ellipsoid_area(b, a, b) == pytest.approx(prolate, rel=1e-13)
    assert vf.ellipsoid_area(1.0, 0.6, 0.4) == pytest.approx(vf.ellipsoid_area(0.4, 1.0, 0.6), rel=1e-15)


# ----------------------------------------------------------------------------------- the cases


def test_cases_build_and_are_sane():
    ids = [c.id for c in vf.CASES]
    assert len(ids) >= 16 and len(set(ids)) == len(ids)
    for c in vf.CASES:
        src, dst = c.build()
        assert isinstance(src, core.Surface) and isinstance(dst, core.Surface), c.id
        assert math.isfinite(c.exact) and 0.0 < c.exact <= 1.0, c.id
        assert c.source, c.id
        assert src.area() > 0.0 and dst.area() > 0.0, c.id


RECIPROCAL_PAIRS = [
    ("sphere_in_cube_to_face", "cube_face_to_sphere_inside"),
    ("sphere_to_coaxial_disk", "coaxial_disk_to_sphere"),
    ("concentric_inner_to_outer_inside", "concentric_outer_inside_to_inner"),
    ("hemisphere_inside_to_base", "base_to_hemisphere_inside"),
    ("cylinder_lateral_to_end", "cylinder_end_to_lateral"),
    ("coaxial_cylinders_inner_to_outer", "coaxial_cylinders_outer_to_inner"),
    ("sphere_to_sphere_unequal", "sphere_to_sphere_unequal_reverse"),
    ("ellipsoid_to_enclosing_sphere", "enclosing_sphere_to_ellipsoid"),
]


@pytest.mark.parametrize("forward, backward", RECIPROCAL_PAIRS)
def test_case_pairs_are_reciprocal(forward, backward):
    """A1 F12 = A2 F21 between catalogue entries, with the areas of the built surfaces."""
    f, b = vf.case(forward), vf.case(backward)
    a1, a2 = (s.area() for s in f.build())
    b1, b2 = (s.area() for s in b.build())
    assert a1 == pytest.approx(b2, rel=1e-9) and a2 == pytest.approx(b1, rel=1e-9)
    assert a1 * f.exact == pytest.approx(a2 * b.exact, rel=1e-9)


def test_cases_of_transformed_geometry_keep_their_sizes():
    """The transformed cases really have the sizes their exact values assume."""
    src, dst = vf.case("c11_mirrored_nonuniform_rotated").build()
    assert src.area() == pytest.approx(6.0, rel=1e-12) and dst.area() == pytest.approx(6.0, rel=1e-12)
    p_src, n_src = src.evaluate(np.array([0.5]), np.array([0.5]))
    p_dst, n_dst = dst.evaluate(np.array([0.5]), np.array([0.5]))
    gap = p_dst[0] - p_src[0]
    assert np.linalg.norm(gap) == pytest.approx(0.5, rel=1e-12)
    assert n_src[0] @ gap > 0 and n_dst[0] @ gap < 0  # fronts face each other
    ellipse = vf.case("sphere_to_ellipse_nonuniform_scale").build()[1]
    assert ellipse.area() == pytest.approx(math.pi * 2.0 * 0.7, rel=1e-9)
