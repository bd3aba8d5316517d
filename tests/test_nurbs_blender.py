"""NurbsSurface.from_blender against Blender's own tessellation of NURBS surface objects.

Blender (source/blender/blenkernel/intern/displist.cc, `evaluate_surface_object`, and curve.cc,
`BKE_nurb_makeFaces`) samples each surface spline on a grid of
totu = point_count_u * resolution_u by totv = point_count_v * resolution_v parameters:
u_k = start + k * step with [start, end] = [knots[order - 1], knots[n]] (n = point_count, or
point_count + order - 1 for a cyclic direction) and step = (end - start) / (totu - 1), or
/ totu when cyclic (the seam is not repeated). It accumulates u += step in float32. The
mesh keeps that grid's vertex order: vertex k_u * totv + k_v. Everything is in the object's
local coordinates. The float32 sum may overshoot the last parameter by an ulp; Blender then
extrapolates the last span while we clamp to the domain, a difference of ~1e-6 of the size.
"""

import numpy as np
import pytest

from core.nurbs import NurbsSurface

pytestmark = pytest.mark.blender
bpy = pytest.importorskip("bpy")

# Blender evaluates in float32: positions agree to a few float32 ulps of the object's size
RTOL = 1e-5


@pytest.fixture(autouse=True)
def empty_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def surface_from_spline(spline):
    """Our NurbsSurface for one bpy NURBS surface spline."""
    co = np.empty(len(spline.points) * 4, np.float32)
    spline.points.foreach_get("co", co)
    return NurbsSurface.from_blender(
        co.reshape(-1, 4),
        spline.order_u,
        spline.order_v,
        spline.point_count_u,
        spline.point_count_v,
        use_endpoint_u=spline.use_endpoint_u,
        use_endpoint_v=spline.use_endpoint_v,
        use_bezier_u=spline.use_bezier_u,
        use_bezier_v=spline.use_bezier_v,
        use_cyclic_u=spline.use_cyclic_u,
        use_cyclic_v=spline.use_cyclic_v,
    )


def blender_samples(domain, count, resolution, cyclic):
    """The parameters Blender's `BKE_nurb_makeFaces` samples along one direction.

    Returns
    -------
    ndarray, shape (count * resolution,)
        float32-accumulated values, as Blender computes them, stored in float64.
    """
    start, end = (np.float32(x) for x in domain)
    total = count * resolution
    step = np.float32(end - start) / np.float32(total if cyclic else total - 1)
    out = np.empty(total)
    t = start
    for k in range(total):
        out[k] = t
        t = np.float32(t + step)
    return out


def compare_with_blender(obj):
    """Max |our P - Blender's vertex| / object size over the evaluated mesh, for a 1-spline object."""
    (spline,) = obj.data.splines
    surface = surface_from_spline(spline)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    verts = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", verts)
    evaluated.to_mesh_clear()
    u = blender_samples(surface.domain[0], spline.point_count_u, spline.resolution_u, spline.use_cyclic_u)
    v = blender_samples(surface.domain[1], spline.point_count_v, spline.resolution_v, spline.use_cyclic_v)
    assert verts.size == 3 * u.size * v.size, "Blender's vertex count is not totu * totv"
    # our surface is clamped to its domain (evaluating outside it is an error)
    u, v = np.clip(u, *surface.domain[0]), np.clip(v, *surface.domain[1])
    ours = surface.evaluate(u[:, None], v[None, :])[0].reshape(-1, 3)
    size = np.abs(verts).max()
    return np.abs(ours - verts.reshape(-1, 3)).max() / size


def add(kind, **kwargs):
    getattr(bpy.ops.surface, f"primitive_nurbs_surface_{kind}_add")(**kwargs)
    return bpy.context.active_object


def edit_spline(obj, **settings):
    """Set spline properties (RNA updates recompute Blender's knots and clamp orders)."""
    (spline,) = obj.data.splines
    for name, value in settings.items():
        setattr(spline, name, value)
    obj.data.update_tag()
    return spline


def set_points(obj, change):
    """Apply change(co) to the spline's (N, 4) point array (xyz local, 4th = weight)."""
    (spline,) = obj.data.splines
    co = np.empty(len(spline.points) * 4, np.float32)
    spline.points.foreach_get("co", co)
    spline.points.foreach_set("co", change(co.reshape(-1, 4)).astype(np.float32).ravel())
    obj.data.update_tag()


@pytest.mark.parametrize("kind", ["surface", "sphere", "cylinder", "torus"])
def test_primitives_match_blender(kind):
    """Blender's NURBS primitives: plain 4x4 cubic, sphere (poles, cyclic v), cylinder, torus."""
    obj = add(kind)
    assert compare_with_blender(obj) < RTOL


def test_weights_and_moved_points_match_blender():
    """A sphere with random weights in [0.2, 5] and jittered control points."""
    obj = add("sphere")
    rng = np.random.default_rng(11)

    def jitter(co):
        co[:, :3] += 0.2 * rng.standard_normal((len(co), 3))
        co[:, 3] = 10 ** rng.uniform(np.log10(0.2), np.log10(5.0), len(co))
        return co

    set_points(obj, jitter)
    assert compare_with_blender(obj) < RTOL


@pytest.mark.parametrize(
    "kind, settings",
    [
        ("surface", dict(use_endpoint_u=True, use_endpoint_v=True)),
        ("surface", dict(order_u=3, order_v=2, use_endpoint_v=True)),
        ("surface", dict(order_v=3, use_bezier_v=True, use_endpoint_u=True, resolution_u=3)),
        ("surface", dict(order_u=6, resolution_u=2, resolution_v=7)),  # clamped to order 4
        ("surface", dict(use_cyclic_u=True, order_u=3)),
        ("surface", dict(use_cyclic_u=True, use_endpoint_u=True, use_cyclic_v=True)),
        ("cylinder", dict(use_endpoint_u=False, use_bezier_u=False)),
        ("cylinder", dict(use_bezier_u=False, order_u=4)),
        ("torus", dict(use_bezier_u=False, use_bezier_v=False, order_u=4, resolution_v=5)),
        ("torus", dict(use_endpoint_v=False, order_v=2)),
        ("sphere", dict(use_bezier_u=False, resolution_u=6)),
        ("sphere", dict(use_endpoint_u=False, use_bezier_u=False, order_v=4, use_bezier_v=False)),
    ],
    ids=lambda x: x if isinstance(x, str) else "-".join(f"{k}={v}" for k, v in x.items()),
)
def test_edited_flags_and_orders_match_blender(kind, settings):
    """Endpoint / Bezier / cyclic / order / resolution edits, each with random weights."""
    obj = add(kind)
    edit_spline(obj, **settings)
    rng = np.random.default_rng(len(settings))

    def reweight(co):
        co[:, 3] = rng.uniform(0.3, 3.0, len(co))
        return co

    set_points(obj, reweight)
    spline = obj.data.splines[0]
    assert spline.order_u <= spline.point_count_u
    assert compare_with_blender(obj) < RTOL


def test_object_transform_stays_out_of_local_coordinates():
    """Spline points and the evaluated mesh are both local: a moved, scaled object still matches."""
    obj = add("torus", location=(3.0, -1.0, 2.0), rotation=(0.3, 0.2, 0.1), scale=(2.0, 2.0, 2.0))
    assert compare_with_blender(obj) < RTOL
