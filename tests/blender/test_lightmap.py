"""Results at any mesh resolution: lightmaps and refined twins, on the installed extension.

A one-quad floor has four vertices, so its vertex colours cannot show a shadow; its lightmap
(the radiosity gathered at every texel through a UV map) and its refined twin (split where the
radiosity varies) must. The scenes are lit by an area light above a sphere; the sphere's shadow
is the oracle: under the sphere the floor is darker than the same distance from the light
elsewhere.
"""

import os

import numpy as np
import pytest
from blender_helpers import ROOT, bpy, material, snapshot

pytestmark = pytest.mark.blender

SIZE = 6.0  # floor side (m), centred at the origin, UVMap u = x / SIZE + 1/2, v = y / SIZE + 1/2
SPHERE = dict(location=(0.0, 0.0, 0.9), radius=0.6)


def build(floor_cuts=1, output="LIGHTMAP", size=32, uv="UVMap"):
    """A floor of floor_cuts x floor_cuts quads, a sphere over its centre, an area light above."""
    if floor_cuts == 1:
        bpy.ops.mesh.primitive_plane_add(size=SIZE)
    else:
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=floor_cuts, y_subdivisions=floor_cuts, size=SIZE)
    floor = bpy.context.active_object
    floor.name = "Floor"
    assert len(floor.data.polygons) == floor_cuts**2
    floor.data.materials.append(material("FloorGrey", base=(0.6, 0.6, 0.6)))
    floor.curved_radiosity_output = output
    floor.curved_radiosity_lightmap_size = size
    floor.curved_radiosity_lightmap_uv = uv
    floor.curved_radiosity_refine_tol = 0.05
    floor.curved_radiosity_refine_min_edge = 0.05
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, **SPHERE)
    bpy.context.active_object.name = "Ball"
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 4))
    light = bpy.context.active_object
    light.data.energy = 300.0
    light.data.size = 1.0
    bpy.context.scene.curved_radiosity.quality = "DRAFT"
    bpy.context.view_layer.update()
    return floor


def compute():
    assert bpy.ops.curved_radiosity.compute() == {"FINISHED"}


def lightmap(name="Floor"):
    """The baked image of `name` as (H, W, 4) float32, and the image."""
    image = next(i for i in bpy.data.images if i.get("_curved_radiosity_lightmap") == name)
    W, H = image.size
    pixels = np.empty(W * H * 4, np.float32)
    image.pixels.foreach_get(pixels)
    return pixels.reshape(H, W, 4), image


def texel_at(pixels, x, y):
    """The floor texel at world (x, y) through UVMap."""
    H, W = pixels.shape[:2]
    i = int(np.clip((y / SIZE + 0.5) * H, 0, H - 1))
    j = int(np.clip((x / SIZE + 0.5) * W, 0, W - 1))
    return pixels[i, j, :3]


def test_one_quad_floor_shows_the_sphere_shadow(addon):
    """Under the sphere the floor's lightmap is darker than at points as far from the light's
    axis on the ring around the shadow; the four vertex colours alone show no shadow at all."""
    build()
    compute()
    pixels, image = lightmap()
    assert image.is_float and image.size[:] == (32, 32)
    assert np.all(pixels[..., 3] == 1.0) and np.all(np.isfinite(pixels))
    under = texel_at(pixels, 0.0, 0.0).mean()
    # same distance from the light's foot, beside the sphere's shadow (radius ~0.8 m) on all sides
    beside = [texel_at(pixels, 1.5 * c, 1.5 * s).mean() for c, s in ((1, 0), (0, 1), (-1, 0), (0, -1))]
    assert under < 0.5 * min(beside), (under, beside)
    # the shown material is the lightmap's: UV map -> this image -> emission
    floor = bpy.data.objects["Floor"]
    nodes = floor.material_slots[0].material.node_tree.nodes
    assert any(n.type == "TEX_IMAGE" and n.image == image for n in nodes)
    assert any(n.type == "UVMAP" and n.uv_map == "UVMap" for n in nodes)


def test_automatic_solver_is_hierarchical_for_lightmaps_only(addon):
    """The default solver (Automatic) takes the hierarchical path when an object bakes a lightmap
    or a refined twin (their detail at contacts and seams needs its sub-patches), all pairs for
    vertex colours alone: the job's settings hold the path, and the report line names it."""
    assert bpy.context.scene.curved_radiosity.method == "AUTO"
    floor = build()
    for output, solver, name in (
        ("LIGHTMAP", "hierarchical", "Hierarchical"),
        ("VERTEX", "pairs", "All Pairs"),
        ("REFINED", "hierarchical", "Hierarchical"),
    ):
        floor.curved_radiosity_output = output
        job = addon.pipeline.prepare(bpy.context)
        assert job.settings.method == solver, output
        compute()
        report = bpy.context.scene.curved_radiosity.last_report
        assert report.endswith(f"({name})"), (output, report)


@pytest.mark.parametrize(
    "cuts",
    [
        16,
        pytest.param(
            64,
            marks=[
                pytest.mark.slow,
                pytest.mark.skipif(
                    not os.environ.get("RADIOSITY_SLOW"),
                    reason="a 64 x 64 floor (4,096 faces) takes ~150 s (hierarchical): set RADIOSITY_SLOW=1",
                ),
            ],
        ),
    ],
)
def test_lightmap_is_independent_of_the_mesh_resolution(addon, cuts):
    """A 1-quad floor and a cuts x cuts floor under the same light give the same lightmap through
    the same UV map (relative rms and largest texel difference), shadow included."""
    maps = []
    for cuts in (1, cuts):
        bpy.ops.wm.read_homefile(use_empty=True)
        build(floor_cuts=cuts, size=24)
        compute()
        maps.append(lightmap()[0][..., :3].astype(np.float64))
    coarse, fine = maps
    scale = coarse.mean()
    rms = np.sqrt(np.mean((coarse - fine) ** 2)) / scale
    assert rms < 0.01, rms
    assert np.abs(coarse - fine).max() < 0.05 * coarse.max()
    # and both show the shadow
    assert texel_at(fine, 0, 0).mean() < 0.5 * texel_at(fine, 1.5, 0).mean()


def test_lightmap_through_a_generated_uv_map(addon):
    """With no UV map named, a non-overlapping one is generated by Lightmap Pack and added to
    the result mesh (the user's active and render UV maps stay); Clear removes it."""
    floor = build(uv="")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=8, ring_count=4, radius=0.3, location=(2, 2, 0.3))
    before = snapshot()
    compute()
    layers = floor.data.uv_layers
    assert "Radiosity Lightmap" in layers
    assert layers.active.name == "UVMap" and layers["UVMap"].active_render
    uv = np.empty(len(floor.data.loops) * 2, np.float32)
    layers["Radiosity Lightmap"].uv.foreach_get("vector", uv)
    assert uv.min() >= 0.0 and uv.max() <= 1.0
    pixels, _ = lightmap()
    assert pixels[..., 3].sum() > 0.5 * pixels[..., 3].size  # most of the image is the floor
    assert bpy.ops.curved_radiosity.clear() == {"FINISHED"}
    assert snapshot() == before


def test_clear_restores_the_scene_exactly(addon):
    """Compute with a lightmap on one object and a refined twin on another, show originals and
    results again, clear: objects, meshes (attributes, UV maps), materials, images and
    collections are as before."""
    build()
    bpy.data.objects["Ball"].curved_radiosity_output = "REFINED"
    bpy.data.objects["Ball"].data.materials.append(material("BallRed", base=(0.8, 0.2, 0.2)))
    before = snapshot()
    compute()
    assert snapshot() != before
    assert bpy.ops.curved_radiosity.show(mode="ORIGINAL") == {"FINISHED"}
    assert bpy.ops.curved_radiosity.show(mode="RESULT") == {"FINISHED"}
    floor = bpy.data.objects["Floor"]
    assert floor.material_slots[0].material.get("_curved_radiosity_lightmap") == "Floor"
    assert bpy.ops.curved_radiosity.clear() == {"FINISHED"}
    assert snapshot() == before


def test_save_and_reopen_keep_the_lightmap(addon, tmp_path):
    """The image is packed into the .blend (full float): reopened, the pixels are identical and
    the view material still shows it; Clear after reopening restores the scene."""
    build()
    before = snapshot()
    compute()
    pixels, image = lightmap()
    assert image.packed_file is not None
    path = tmp_path / "lit.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    again, image = lightmap()
    assert np.array_equal(again, pixels)
    nodes = bpy.data.objects["Floor"].material_slots[0].material.node_tree.nodes
    assert any(n.type == "TEX_IMAGE" and n.image == image for n in nodes)
    assert bpy.ops.curved_radiosity.clear() == {"FINISHED"}
    assert snapshot() == before


def refined_twin(name):
    twin = next(o for o in bpy.data.objects if o.get("_curved_radiosity_twin_of") == name)
    mesh = twin.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    M = np.array(twin.matrix_world)
    co = co.reshape(-1, 3).astype(np.float64) @ M[:3, :3].T + M[:3, 3]
    colour = np.empty(len(mesh.vertices) * 4, np.float32)
    mesh.color_attributes["Radiosity"].data.foreach_get("color", colour)
    return twin, co, colour.reshape(-1, 4)[:, :3]


def test_refined_twin_refines_under_the_shadow_edge_only(addon):
    """A one-quad floor's refined twin has many vertices in the ring of the sphere's penumbra
    and few where the light varies slowly (the outer band); its colours show the shadow; it
    keeps the floor's UV map (u = x / SIZE + 1/2 exactly, as the plane's) and material, lives in
    the Radiosity collection, and Clear removes it."""
    floor = build(output="REFINED")
    before = snapshot()
    compute()
    twin, co, colour = refined_twin("Floor")
    assert floor.hide_render and not twin.hide_render
    assert any(c.name == "Radiosity" for c in twin.users_collection)
    r = np.hypot(co[:, 0], co[:, 1])
    # the shadow of a 0.6 m sphere at 0.9 m under a 1 m light at 4 m: umbra ~0.5 m, penumbra ~1 m
    ring = (r > 0.4) & (r < 1.3)
    outer = np.maximum(np.abs(co[:, 0]), np.abs(co[:, 1])) > 2.2  # band along the border
    ring_area = np.pi * (1.3**2 - 0.4**2)
    outer_area = SIZE**2 - 4.4**2
    density_ring, density_outer = ring.sum() / ring_area, outer.sum() / outer_area
    assert density_ring > 10.0 * density_outer, (density_ring, density_outer)
    centre = colour[np.argmin(r)].mean()
    assert centre < 0.5 * colour[(r > 1.1) & (r < 2.0)].mean(axis=1).min()
    # UVs carried over exactly from the user's map, per corner
    mesh = twin.data
    uv = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers["UVMap"].uv.foreach_get("vector", uv)
    corner_vertex = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corner_vertex)
    expected = co[corner_vertex, :2] / SIZE + 0.5
    assert np.abs(uv.reshape(-1, 2) - expected).max() < 1e-5
    assert [m.name for m in mesh.materials] == ["FloorGrey"]
    assert bpy.ops.curved_radiosity.clear() == {"FINISHED"}
    assert snapshot() == before


def test_refined_twin_keeps_a_flat_region_coarse(addon):
    """Without the sphere the light on the floor varies smoothly: the twin stays far coarser
    than uniform subdivision at the minimum edge (under 5 % of its vertices)."""
    floor = build(output="REFINED")
    bpy.data.objects.remove(bpy.data.objects["Ball"])
    compute()
    twin, co, _ = refined_twin("Floor")
    uniform = (SIZE / floor.curved_radiosity_refine_min_edge) ** 2
    assert len(co) < 0.05 * uniform, len(co)


def test_bad_output_settings_are_named(addon):
    """A UV map that does not exist stops the compute with an error naming the object and map,
    before anything in the scene changes."""
    build(uv="NoSuchMap")
    before = snapshot()
    with pytest.raises(RuntimeError, match="'Floor'.*NoSuchMap"):
        bpy.ops.curved_radiosity.compute()
    assert snapshot() == before


def test_headless_lightmap_and_refine(addon, tmp_path):
    """`--lightmap` and `--refine` on the command line write a lit .blend with the packed
    lightmap and the refined twin."""
    import subprocess
    import sys

    build(output="VERTEX")
    scene = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene))
    out = tmp_path / "lit.blend"
    command = [
        sys.executable, "-m", "addon.headless", str(scene), "--out", str(out), "--quality", "DRAFT",
        "--lightmap", "Floor", "--lightmap-size", "16", "--lightmap-uv", "UVMap", "--refine", "Ball",
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stderr
    bpy.ops.wm.open_mainfile(filepath=str(out))
    pixels, image = lightmap()
    assert image.size[:] == (16, 16) and image.packed_file is not None
    assert texel_at(pixels, 0, 0).mean() < 0.5 * texel_at(pixels, 1.5, 0).mean()
    twin, _, _ = refined_twin("Ball")
    assert len(twin.data.polygons) > 0
    bad = subprocess.run(
        [sys.executable, "-m", "addon.headless", str(scene), "--lightmap", "Nothing"],
        capture_output=True, text=True, cwd=ROOT, timeout=600,
    )  # fmt: skip
    assert bad.returncode == 2 and "'Nothing'" in bad.stderr


SCENE_05 = ROOT / "blender_scenes" / "05_stress_many_spheres.blend"


@pytest.mark.slow
@pytest.mark.skipif(
    not os.environ.get("RADIOSITY_SLOW"),
    reason="example 05 solves twice and refines around 144 shadows (~4 min): set RADIOSITY_SLOW=1",
)
def test_scene_05_shows_the_spheres_shadows(addon):
    """Example 05 (12 x 12 spheres of radius 0.5 at 2 m spacing, 0.6 m up, over a 24 m floor
    of one quad): through the lightmap, and then (relit: same form factors) through the refined
    twin, the floor is darker near a sphere's foot than midway between four spheres, for spheres
    across the floor."""
    bpy.ops.wm.open_mainfile(filepath=str(SCENE_05))
    floor = bpy.data.objects["Floor"]
    assert len(floor.data.polygons) == 1
    floor.curved_radiosity_output = "LIGHTMAP"
    floor.curved_radiosity_lightmap_size = 96
    floor.curved_radiosity_lightmap_uv = "UVMap"
    floor.curved_radiosity_refine_tol = 0.3
    floor.curved_radiosity_refine_min_edge = 0.2
    floor.curved_radiosity_refine_max_edge = 0.5
    bpy.context.scene.curved_radiosity.quality = "DRAFT"
    # (its balls hang clear of the floor: no contact for sub-patches to resolve, and all pairs
    # is about twice as fast here as the hierarchical path Automatic would pick)
    bpy.context.scene.curved_radiosity.method = "PAIRS"
    compute()
    side = 24.0
    pixels, _ = lightmap()
    H, W = pixels.shape[:2]

    def from_lightmap(x, y):
        return pixels[int((y / side + 0.5) * H), int((x / side + 0.5) * W), :3].mean()

    floor.curved_radiosity_output = "REFINED"
    assert bpy.ops.curved_radiosity.compute(relight=True) == {"FINISHED"}
    _, co, colour = refined_twin("Floor")

    def from_twin(x, y):
        return colour[np.argmin(np.hypot(co[:, 0] - x, co[:, 1] - y))].mean()

    # spheres stand at odd coordinates; the sun shifts each shadow a little from the foot: take
    # the darkest of a few samples around the foot against the point midway between spheres
    for value in (from_lightmap, from_twin):
        for x, y in ((-5.0, -5.0), (1.0, 1.0), (5.0, -3.0)):
            under = min(value(x + dx, y + dy) for dx in (-0.25, 0, 0.25) for dy in (-0.25, 0, 0.25))
            between = value(x + 1.0, y + 1.0)
            assert under < 0.8 * between, (value.__name__, x, y, under, between)


def test_adaptive_lightmap_matches_every_texel_gathered(addon):
    """The adaptive lightmap (tolerance 0.01) agrees with the one gathered at every texel
    (tolerance 0) within about that tolerance of the brightest texel, while gathering well under
    half of the texels."""
    build(size=96)
    floor = bpy.data.objects["Floor"]
    maps, jobs = [], []
    for tol in (0.0, 0.01):
        floor.curved_radiosity_lightmap_tol = tol
        jobs.append(addon.pipeline.compute(bpy.context))
        maps.append(lightmap()[0][..., :3].astype(np.float64))
    every, adaptive = maps
    assert jobs[0].requests.lightmaps[0].gathered == 96 * 96
    assert jobs[1].requests.lightmaps[0].gathered < 0.5 * 96 * 96
    assert np.abs(adaptive - every).max() < 0.02 * every.max()


def test_computing_twice_equals_computing_once(addon):
    """A second compute (generated UV map, lightmap, refined twin) replaces the first: the same
    objects, UV maps, images and materials, and Clear still restores the scene."""
    build(uv="")
    bpy.data.objects["Ball"].curved_radiosity_output = "REFINED"
    before = snapshot()
    compute()
    once = snapshot()
    compute()
    assert snapshot() == once
    assert bpy.ops.curved_radiosity.clear() == {"FINISHED"}
    assert snapshot() == before


def test_a_users_uv_map_named_like_ours_is_never_overwritten(addon):
    """A user's own UV map called "Radiosity Lightmap" stops a generated-map bake with an error
    naming it; the scene is unchanged."""
    floor = build(uv="")
    floor.data.uv_layers.new(name="Radiosity Lightmap")
    before = snapshot()
    with pytest.raises(RuntimeError, match="'Floor'.*Radiosity Lightmap"):
        bpy.ops.curved_radiosity.compute()
    assert snapshot() == before
