"""NURBS surface objects: one core NurbsSurface per spline, sampled where Blender tessellates.

The (u, v) of each item sample must land on the vertex of Blender's own evaluated mesh with the
same index (the tessellation rule of addon/tessellation.py), in world space, so results can be
written onto a mesh twin made from that evaluation.
"""

import itertools
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from blender_helpers import bpy, collect, evaluated_world_positions

pytestmark = pytest.mark.blender


def add(kind, **kwargs):
    getattr(bpy.ops.surface, f"primitive_nurbs_surface_{kind}_add")(**kwargs)
    return bpy.context.active_object


def max_error(addon, obj):
    """Largest |P(u, v) - Blender vertex| over the object's samples, relative to its size."""
    collected = collect(addon)
    items = [i for i in collected.surfaces if i.target == obj.name]
    world = evaluated_world_positions(obj)
    assert collected.targets[obj.name].n_vertices == len(world)
    assert collected.targets[obj.name].twin
    covered = np.concatenate([i.vertices for i in items])
    assert np.array_equal(np.sort(covered), np.arange(len(world)))
    errors = [
        np.abs(i.surface.evaluate(i.params[:, 0], i.params[:, 1])[0] - world[i.vertices]).max() for i in items
    ]
    return max(errors) / np.abs(world).max(), items


@pytest.mark.parametrize("kind", ["surface", "sphere", "cylinder", "torus"])
def test_primitives_in_world_space(addon, kind):
    """Moved, rotated, non-uniformly scaled primitives: samples hit Blender's vertices (float32 level)."""
    obj = add(kind, location=(2.0, -1.0, 0.5), rotation=(0.3, -0.2, 0.9))
    obj.scale = (1.5, 0.5, 2.0)
    bpy.context.view_layer.update()
    error, items = max_error(addon, obj)
    assert error < 1e-5
    assert [type(i.surface).__name__ for i in items] == ["NurbsSurface"]


def test_several_splines_follow_each_other(addon):
    """A joined object (plain patch + sphere): spline vertex blocks in spline order."""
    first = add("surface")
    add("sphere", location=(4.0, 0.0, 0.0))
    bpy.ops.object.select_all(action="SELECT")
    bpy.context.view_layer.objects.active = first
    bpy.ops.object.join()
    error, items = max_error(addon, first)
    assert error < 1e-5 and len(items) == 2
    assert items[1].vertices[0] == len(items[0].vertices)


def test_resolution_and_weights(addon):
    """Edited resolution, order and weights still map exactly."""
    obj = add("sphere")
    (spline,) = obj.data.splines
    spline.resolution_u, spline.resolution_v = 3, 7
    co = np.empty(len(spline.points) * 4, np.float32)
    spline.points.foreach_get("co", co)
    co = co.reshape(-1, 4)
    co[:, 3] = np.linspace(0.5, 2.0, len(co))
    spline.points.foreach_set("co", co.ravel())
    obj.data.update_tag()
    error, _ = max_error(addon, obj)
    assert error < 1e-5


def test_degenerate_surface_is_reported_by_name(addon):
    """All control points at one spot: the object is skipped, naming object and spline."""
    obj = add("surface")
    obj.name = "Crumpled"
    (spline,) = obj.data.splines
    spline.points.foreach_set("co", np.tile([0.0, 0.0, 0.0, 1.0], len(spline.points)).astype(np.float32))
    collected = collect(addon)
    assert not collected.targets and any("'Crumpled', spline 0" in m for m in collected.skipped)


def test_tessellation_parameters(addon):
    """Blender's float32 running sum, clipped to the domain; cyclic directions skip the seam."""
    u = addon.tessellation.sample_parameters((0.0, 1.0), 4, 3, cyclic=False)
    assert u.size == 12 and u[0] == 0.0 and u[-1] == pytest.approx(1.0, abs=1e-6) and u[-1] <= 1.0
    v = addon.tessellation.sample_parameters((0.0, 2.0), 4, 2, cyclic=True)
    assert v.size == 8 and v[-1] == pytest.approx(2.0 * 7 / 8, abs=1e-6)
    gu, gv = addon.tessellation.grid_parameters(((0.0, 1.0), (0.0, 2.0)), (4, 4), (3, 2), (False, True))
    assert gu.size == 96 and gu[8] == u[1] and gv[9] == v[1]


# --------------------------------------------------------------------------- every flag, every order
@pytest.mark.parametrize("method", ["pairs", "hierarchical"])
def test_a_net_folded_onto_itself_is_skipped_and_the_rest_solved(addon, method):
    """Blender's NURBS Surface primitive with Cyclic U and V, Bezier V, orders 6 and 3 (case 946
    of `benchmarks.nurbs_primitives`) folds onto itself: a patch's form factors sum to ~7, and
    the solve cannot succeed (it was refused, taking the floor beside it along). Now the run goes
    through: the net is skipped with a warning naming it (no result written to it, as for any
    object that cannot take part), and the floor is lit as if the net were absent (the same
    scene without it gives the same floor)."""
    job, values = _floor_lit_with(addon, method, folded=True)
    (warning,) = [w for w in job.collected.warnings if "passes through itself" in w]
    assert warning.startswith("'SurfPatch': ") and warning.endswith(": skipped")
    assert job.collected.skipped == [warning]
    assert "SurfPatch" not in job.collected.targets
    assert not any(item.target == "SurfPatch" for item in job.collected.surfaces)
    assert bpy.data.objects.get("SurfPatch radiosity") is None
    alone, reference = _floor_lit_with(addon, method, folded=False)
    assert not alone.collected.skipped
    np.testing.assert_allclose(values, reference, rtol=1e-9)
    assert values.min() > 0


def _floor_lit_with(addon, method, folded):
    """(job, the floor's vertex radiance) of a compute of a floor under a point light, with the
    folded net above it if `folded`."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0, 0, -1.5))
    floor = bpy.context.active_object
    if folded:
        net = add("surface")
        (spline,) = net.data.splines
        settings = dict(use_cyclic_u=True, use_cyclic_v=True, use_bezier_v=True, order_u=6, order_v=3)
        for name, value in settings.items():
            setattr(spline, name, value)
        net.data.update_tag()
        net.curved_radiosity_patches = (2, 2)
    bpy.ops.object.light_add(type="POINT", location=(0.3, 0.2, 4.0))
    bpy.context.active_object.data.energy = 200.0
    settings = addon.solve.Settings(tol=1e-2, occlusion=True, max_bounces=None, method=method)
    job = addon.pipeline.compute(bpy.context, settings)
    return job, addon.adapter.read_color_attribute(floor.data, "Radiosity")[:, :3]


# Runs in a child process (bpy as a module, the built extension installed into a fresh user
# folder) so that a hang or runaway memory fails the test by its timeout instead of hanging
# the suite. For each case: a fresh empty scene, the primitive with the spline settings, 2 x 2
# patches (or the case's "patches") and one point light, solved through the add-on's pipeline
# at tol 1e-2; it prints the outcome, the extreme values written, the time and the peak of
# traced (numpy and Python) allocations of that case, and how far the process's peak resident
# memory rose above its peak once bpy and the extension were loaded (the start-up's own peak
# holds file-backed pages of bpy's library, whose count follows the page cache: 0.6-1.0 GB).
STRESS = """
import importlib, json, os, resource, sys, tempfile, time, tracemalloc
import numpy as np
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="curved-radiosity-nurbs-")
import bpy
zip_path, cases = sys.argv[1], json.load(open(sys.argv[2]))
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
addon = importlib.import_module("bl_ext.user_default.curved_radiosity")
start_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
for case in cases:
    bpy.ops.wm.read_homefile(use_empty=True)
    getattr(bpy.ops.surface, "primitive_nurbs_surface_%s_add" % case["kind"])()
    obj = bpy.context.active_object
    (spline,) = obj.data.splines
    for name, value in case["settings"].items():
        setattr(spline, name, value)
    obj.data.update_tag()
    obj.curved_radiosity_patches = tuple(case.get("patches", (2, 2)))
    bpy.ops.object.light_add(type="POINT", location=(0.3, 0.2, 4.0))
    bpy.context.active_object.data.energy = 200.0
    settings = addon.solve.Settings(tol=1e-2, occlusion=True, max_bounces=None)
    tracemalloc.start()
    start = time.perf_counter()
    try:
        addon.pipeline.compute(bpy.context, settings)
        twin = bpy.data.objects[obj.name + " radiosity"]
        values = addon.adapter.read_color_attribute(twin.data, "Radiosity")[:, :3]
        outcome = "solved" if values.size and np.isfinite(values).all() else "bad result"
        lit, low = float(values.max()), float(values.min())
    except addon.pipeline.PipelineError as error:
        outcome, lit, low = "refused: %s" % error, None, None
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    record = dict(case, outcome=outcome, lit=lit, low=low, seconds=seconds, peak=peak, rss=rss - start_rss,
                  orders=[spline.order_u, spline.order_v])
    print("CASE " + json.dumps(record), flush=True)
"""

FLAGS = ("use_cyclic", "use_endpoint", "use_bezier")


def flag_settings(values_u, values_v):
    """Spline settings with the three flags of each direction."""
    names = [f"{f}_u" for f in FLAGS] + [f"{f}_v" for f in FLAGS]
    return dict(zip(names, [*values_u, *values_v]))


def every_flag():
    """The 4 x 4 NURBS Surface primitive (order 4) with all 64 flag combinations in u and v."""
    combos = itertools.product(itertools.product([False, True], repeat=3), repeat=2)
    return [dict(kind="surface", settings=flag_settings(a, b)) for a, b in combos]


# (cyclic, endpoint, Bezier) along one direction of the torus, tried with each order
ORDER_FLAGS = [(False, False, False), (True, False, False), (False, True, False), (True, True, True)]


def every_order():
    """The 8 x 8 torus (cyclic, Bezier, endpoint in both directions), one patch: orders 2 .. 6
    in u with four flag sets along u, and likewise in v, the other direction as Blender made it."""
    cases = []
    for axis, order, flags in itertools.product("uv", range(2, 7), ORDER_FLAGS):
        settings = {f"{f}_{axis}": value for f, value in zip(FLAGS, flags)}
        settings[f"order_{axis}"] = order
        cases.append(dict(kind="torus", settings=settings, patches=(1, 1)))
    return cases


def run_cases(extension_zip, tmp_path, cases, timeout):
    """Run `cases` in a child process; returns its records, one per case."""
    listing = tmp_path / "cases.json"
    listing.write_text(json.dumps(cases))
    command = [sys.executable, "-c", STRESS, str(extension_zip), str(listing)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stderr[-3000:]
    records = [json.loads(line[5:]) for line in done.stdout.splitlines() if line.startswith("CASE ")]
    assert len(records) == len(cases), done.stderr[-3000:]
    return records


# Known defect (issue "Every pair of surface kinds"): on self-touching cyclic nets (a net its cyclic
# flags fold onto itself: coincident layers) the generic NURBS pair factors are so far off that rows
# of F sum above 1/rho, and the solver refuses the system as numerically singular rather than return
# negative radiosities: a core.CrossingSurfaceError, on which the add-on skips the object with a
# warning (alone in its scene, the run is then refused as having nothing to light, naming it). Such
# refusals must stay named, bounded and cyclic, and no more than this many per run (a regression
# fails). Whether such a system's
# solution turns negative depends on E too: when the lights' patch irradiance became error
# controlled (its 3 x 3 rule had been up to 16 % off), a fifth cyclic torus net (contraction 1.04-1.08)
# crossed over: the same class, contraction above 1 from the wrong factors.
KNOWN_SINGULAR = 5


def check_records(records, seconds, traced, resident=1e9, known_singular=KNOWN_SINGULAR):
    """Every case solved (finite values written) or refused with the reason, each within
    `seconds` and `traced` bytes, the child process's peak resident memory at most `resident`
    bytes above its start-up's, at most
    `known_singular` refused as numerically singular (all of them cyclic)."""
    singular = []
    for r in records:
        label = f"{r['kind']} {r['settings']} (orders {r['orders']})"
        assert r["outcome"] == "solved" or r["outcome"].startswith("refused: cannot compute radiosity"), label
        # (refused as singular, or skipped as such with nothing else left to light)
        folded = "numerically singular" in r["outcome"] or "passes through itself" in r["outcome"]
        if r["outcome"] != "solved" and folded:
            cyclic = [v for k, v in r["settings"].items() if k.startswith("use_cyclic")]
            # the Surface primitive folds through itself when cyclic both ways
            assert all(cyclic) if r["kind"] == "surface" else any(cyclic), label
            singular.append(f"{label}: {r['outcome']}")
        elif r["outcome"] != "solved":
            # Blender's own rule: Bezier needs more point rows (it draws nothing either)
            assert "Bezier option" in r["outcome"], f"{label}: {r['outcome']}"
        assert r["seconds"] < seconds, f"{label}: {r['seconds']:.1f} s"
        assert r["peak"] < traced, f"{label}: {r['peak'] / 1e6:.0f} MB traced"
    print("refused as numerically singular (known defect):", singular)
    rss, peak = max(r["rss"] for r in records), max(r["peak"] for r in records)
    print(f"peak RSS {rss / 1e6:.0f} MB above start-up, traced {peak / 1e6:.0f} MB")
    assert len(singular) <= known_singular, singular
    assert max(r["rss"] for r in records) < resident, (
        f"peak RSS {max(r['rss'] for r in records) / 1e6:.0f} MB above start-up"
    )


@pytest.mark.slow
def test_every_flag_combination_solves_in_bounded_time_and_memory(extension_zip, tmp_path):
    """NURBS Surface primitive, cyclic / endpoint / Bezier in u and v (64 cases): each converted
    through the add-on and solved with a light, or refused naming Blender's Bezier rule; each
    under 60 s and 300 MB of traced allocations, the whole process under 1 GB resident (the
    order-4 cyclic-u case once grew past 5.9 GB in Blender)."""
    records = run_cases(extension_zip, tmp_path, every_flag(), timeout=1200)
    check_records(records, seconds=60.0, traced=300e6)
    solved = [r for r in records if r["outcome"] == "solved"]
    # (the self-folding doubly cyclic cases may all be refused: KNOWN_SINGULAR above)
    assert len(solved) >= 16
    assert sum(r["lit"] > 0 for r in solved) >= len(solved) // 2


@pytest.mark.slow
def test_every_order_and_flag_solves_in_bounded_time_and_memory(extension_zip, tmp_path):
    """Torus primitive, orders 2 .. 6 with four flag sets along u or along v (40 cases): each
    solved or refused by Blender's Bezier rule, bounded as above; orders are kept (8 points
    allow order 6)."""
    cases = every_order()
    records = run_cases(extension_zip, tmp_path, cases, timeout=1800)
    check_records(records, seconds=60.0, traced=300e6)
    for case, r in zip(cases, records):
        axis = "u" if "order_u" in case["settings"] else "v"
        assert r["orders"]["uv".index(axis)] == case["settings"][f"order_{axis}"]
    assert sum(r["outcome"] == "solved" for r in records) >= 20


@pytest.mark.slow
@pytest.mark.skipif(
    not os.environ.get("RADIOSITY_SLOW"),
    reason="200 cases of the full grid take ~6 min on 2 shared cores: set RADIOSITY_SLOW=1 "
    "(the whole grid: python -m benchmarks.nurbs_primitives)",
)
def test_sampled_full_grid_solves_in_bounded_time_and_memory(extension_zip, tmp_path):
    """A seeded 200 of the full grid (every primitive kind x 64 flag sets x orders 2-6 in u and
    v, `benchmarks.nurbs_primitives.grid`): each solved or refused by name, bounded as above. The
    self-folding cyclic cases refused as singular are at most 1 in 10 (3 of the benchmark's
    100-case sample)."""
    from benchmarks.nurbs_primitives import KINDS, grid

    cases = grid(KINDS, range(2, 7))
    pick = np.random.default_rng(2).choice(len(cases), 200, replace=False)
    records = run_cases(extension_zip, tmp_path, [cases[k] for k in np.sort(pick)], timeout=3600)
    check_records(records, seconds=60.0, traced=300e6, known_singular=len(records) // 10)
    assert sum(r["outcome"] == "solved" for r in records) >= len(records) // 2


def test_self_intersecting_cyclic_surface_gets_no_negative_radiosity(extension_zip, tmp_path):
    """Radiosity is never negative, even on a surface that passes through itself: the 4 x 4 Surface
    primitive cyclic in u and v, whose self pairs' visibility once passed the first ray rule
    unblocked (a row of form factors summed to 1.9 and the solve was refused; before that refusal
    existed the radiosity went down to -0.61), is solved (`tests/test_scene.py`)."""
    settings = flag_settings((True, False, False), (True, False, False))
    (record,) = run_cases(extension_zip, tmp_path, [dict(kind="surface", settings=settings)], timeout=600)
    assert record["outcome"] == "solved" and record["low"] >= 0.0
