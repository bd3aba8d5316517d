"""End to end with the core addon: operators, relighting, cancelling, errors (scene unchanged).

The seed scene has a closed-form answer: an emitting sphere (radiance L, radius R, reflectance 0)
over a square of reflectance rho gives at a square point p, seeing the whole sphere,
E = pi L sin^2(a) cos(t) with sin(a) = R / |c - p| and cos(t) = h / |c - p| (Howell's catalogue,
sphere to a differential area, configuration B-44 with the sphere above the horizon), so the
square's radiance is rho E / pi, and nothing else is lit (the sphere reflects nothing).
"""

import numpy as np
import pytest
from blender_helpers import ROOT, bpy, snapshot

pytestmark = pytest.mark.blender

SEED = ROOT / "blender_scenes" / "01_seed_sphere_over_square.blend"


def attribute(addon, name, which="Radiosity"):
    return addon.adapter.read_color_attribute(bpy.data.objects[name].data, which)[:, :3]


def seed_expected(points, L=5.0, R=0.5, rho=0.5, centre=(0.0, 0.0, 1.5)):
    d = np.asarray(centre) - points
    dist = np.linalg.norm(d, axis=1)
    E = np.pi * L * (R / dist) ** 2 * d[:, 2] / dist
    return rho * E / np.pi


def test_seed_scene_closed_form(addon):
    """Square corners get rho E / pi from the emitting sphere (3 % for the addon's tolerance)."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    bpy.context.scene.curved_radiosity.quality = "HIGH"
    assert bpy.ops.curved_radiosity.compute() == {"FINISHED"}
    square = bpy.data.objects["Square"]
    corners = np.array([v.co for v in square.data.vertices])
    values = attribute(addon, "Square")
    assert values[:, 0] == pytest.approx(seed_expected(corners), rel=0.03)
    assert np.allclose(values[:, 0], values[:, 2])
    sphere = attribute(addon, "Emitter")
    assert sphere == pytest.approx(np.full_like(sphere, 5.0), rel=1e-6)  # emission only


def test_matches_the_core_called_directly(addon):
    """The attribute equals core.Scene's radiosity_at at the same (u, v) for the same input."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    bpy.ops.curved_radiosity.compute()
    core = addon.core
    scene = core.Scene()
    sphere = scene.add(core.Sphere((0, 0, 1.5), 0.5), reflectance=0.0, emission=5.0, two_sided=True)
    quad = core.Quad((-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0))
    square = scene.add(quad, reflectance=0.5, two_sided=True)
    sol = scene.solve(tol=1e-3)
    u, v = np.array([0.0, 1.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0, 1.0])
    ours = sol.radiosity_at(square, u, v)
    corners = np.array([v.co for v in bpy.data.objects["Square"].data.vertices])
    order = [int(np.argmin(np.abs(corners[:, :2] - p).sum(1))) for p in ([-1, -1], [1, -1], [-1, 1], [1, 1])]
    assert attribute(addon, "Square")[order] == pytest.approx(ours, rel=1e-3, abs=1e-9)
    assert sol.radiosity(sphere) == pytest.approx(np.full((sol.radiosity(sphere).shape[0], 3), 5.0))


def test_invoke_without_a_window_runs_to_completion(addon):
    """Headless, INVOKE_DEFAULT (what a UI button calls) falls back to the synchronous execute()."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    assert bpy.ops.curved_radiosity.compute("INVOKE_DEFAULT") == {"FINISHED"}
    assert "Radiosity" in bpy.data.objects["Square"].data.color_attributes


def test_relight_reuses_geometry_and_is_linear(addon):
    """Doubling the emission and relighting doubles the result and reports a relight."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    bpy.ops.curved_radiosity.compute()
    first = attribute(addon, "Square")
    bsdf = bpy.data.materials["Glow"].node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Emission Strength"].default_value *= 2.0
    bpy.ops.curved_radiosity.compute(relight=True)
    assert "relit" in bpy.context.scene.curved_radiosity.last_report
    assert attribute(addon, "Square") == pytest.approx(2.0 * first, rel=1e-6)


def test_cancel_leaves_the_scene_unchanged(addon):
    """A cancel during the solve raises core.Cancelled and writes nothing."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    before = snapshot()
    with pytest.raises(addon.core.Cancelled):
        addon.pipeline.compute(bpy.context, cancel=lambda: True)
    assert snapshot() == before


def test_gather_reports_progress_and_is_the_same_in_any_block_size(addon):
    """The per-vertex gather reports its own stage, rising to 1, and its result does not
    depend on how the points are cut into blocks."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    job = addon.pipeline.prepare(bpy.context)
    session = addon.solve.Session(job.collected)
    sol = session.solve(job.settings)
    seen = []
    small = addon.solve.vertex_radiance(
        sol, session.surface_handles, job.collected, lambda s, f: seen.append((s, f)), block=16
    )
    whole = addon.solve.vertex_radiance(sol, session.surface_handles, job.collected, block=10**9)
    fractions = [f for stage, f in seen]
    assert {stage for stage, _ in seen} == {"gather"}
    assert len(fractions) > 20 and fractions[0] == 0.0 and fractions[-1] == 1.0
    assert np.all(np.diff(fractions) > 0)
    for name, (front, back) in whole.items():
        assert small[name][0] == pytest.approx(front, rel=1e-12, abs=1e-15)
        assert (back is None) == (small[name][1] is None)


def test_cancel_during_the_gather(addon):
    """Cancel after the solve, while vertices are gathered: core.Cancelled, nothing written."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    before = snapshot()
    seen = []
    gathered = lambda: any(stage == "gather" and f > 0 for stage, f in seen)  # noqa: E731
    with pytest.raises(addon.core.Cancelled, match="gather"):
        addon.pipeline.compute(bpy.context, progress=lambda s, f: seen.append((s, f)), cancel=gathered)
    assert ("done", 1.0) in seen and max(f for s, f in seen if s == "gather") < 1.0
    assert snapshot() == before


def test_cancel_from_the_worker_thread(addon):
    """The modal path's worker: cancel() stops the solve; nothing is written."""
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "blender_scenes" / "03_cornell_box.blend"))
    before = snapshot()
    job = addon.pipeline.prepare(bpy.context)
    worker = addon.jobs.BackgroundSolve(lambda progress, cancel: addon.pipeline.run(job, progress, cancel))
    worker.cancel()
    worker.start().wait(60)
    assert isinstance(worker.error, addon.core.Cancelled)
    assert snapshot() == before


@pytest.mark.parametrize("problem", ["no emitters", "unsupported object", "degenerate NURBS"])
def test_errors_name_the_problem_and_change_nothing(addon, problem):
    bpy.ops.mesh.primitive_cube_add()
    if problem != "no emitters":
        bpy.ops.object.light_add(type="POINT", location=(0, 0, 3))
    if problem == "unsupported object":
        # nothing else to light: the refusal names the skipped object
        bpy.data.objects.remove(bpy.data.objects["Cube"])
        bpy.ops.curve.primitive_bezier_circle_add(location=(3, 0, 0))
        bpy.context.active_object.name = "Label"
        match = "'Label'"
    elif problem == "degenerate NURBS":
        bpy.ops.surface.primitive_nurbs_surface_surface_add(location=(0, 3, 0))
        obj = bpy.context.active_object
        obj.name = "Flat"
        spline = obj.data.splines[0]
        spline.points.foreach_set("co", np.tile([1.0, 1.0, 1.0, 1.0], len(spline.points)).astype(np.float32))
        bpy.data.objects.remove(bpy.data.objects["Cube"])
        match = "'Flat', spline 0"
    else:
        match = "no emitters"
    before = snapshot()
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.curved_radiosity.compute()
    assert snapshot() == before


def test_cornell_box_end_to_end_and_clear(addon):
    """All result meshes get attributes; the shell's twin is lit; Clear restores the file's state."""
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "blender_scenes" / "03_cornell_box.blend"))
    bpy.context.scene.curved_radiosity.quality = "DRAFT"
    before = snapshot()
    assert bpy.ops.curved_radiosity.compute() == {"FINISHED"}
    shell = bpy.data.objects["Shell radiosity"]
    lit = addon.adapter.read_color_attribute(shell.data, "Radiosity")
    assert np.all(np.isfinite(lit)) and lit[:, :3].max() > 0.0
    floor = attribute(addon, "Floor")
    assert floor.min() > 0.0 and floor[:, 0].max() < 50.0
    left, right = attribute(addon, "Left").mean(0), attribute(addon, "Right").mean(0)
    assert left[0] > left[1] and right[1] > right[0]  # red and green walls
    assert bpy.ops.curved_radiosity.clear() == {"FINISHED"}
    assert snapshot() == before
