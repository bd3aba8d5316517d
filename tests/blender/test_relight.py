"""Relight Only: the per-vertex gather is kept and re-applied, not run again (addon/solve.py)."""

import numpy as np
import pytest
from blender_helpers import ROOT, bpy, material

pytestmark = pytest.mark.blender

SEED = ROOT / "blender_scenes" / "01_seed_sphere_over_square.blend"


def radiance(job, name):
    return job.solution.radiance[name][0]


def test_relight_applies_the_kept_gather(addon):
    """A relight after a light and material change gathers no point again (one sparse product)
    and equals a full compute of the changed scene to its tolerance."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    first = addon.pipeline.compute(bpy.context)
    assert first.solution.stats["gather_points"] > 0
    glow = bpy.data.materials["Glow"].node_tree.nodes["Principled BSDF"]
    glow.inputs["Emission Strength"].default_value *= 3.0
    grey = bpy.data.materials["Grey"].node_tree.nodes["Principled BSDF"]
    grey.inputs["Base Color"].default_value = (0.2, 0.6, 0.4, 1.0)
    relit = addon.pipeline.compute(bpy.context, relight=True)
    assert relit.solution.relit
    assert "gather_points" not in relit.solution.stats and "relight_gather" in relit.solution.stats["times"]
    full = addon.pipeline.compute(bpy.context)
    assert not full.solution.relit and full.solution.stats["gather_points"] > 0
    for name in ("Square", "Emitter"):
        a, b = radiance(relit, name), radiance(full, name)
        assert np.abs(a - b).max() <= 5e-3 * np.abs(b).max(), name


def test_relight_lighting_a_black_surface_gathers_again(addon):
    """A surface black at the first compute was left out of the kept factors: when it is given
    a colour, the relight falls back to a full gather (and matches a full compute)."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, 3.0), rotation=(np.pi, 0.0, 0.0))
    lid = bpy.context.active_object
    black = material("Black", base=(0.0, 0.0, 0.0))
    black.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    lid.data.materials.append(black)
    addon.pipeline.compute(bpy.context)
    black.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.7, 0.7, 0.7, 1.0)
    relit = addon.pipeline.compute(bpy.context, relight=True)
    assert relit.solution.relit and relit.solution.stats["gather_points"] > 0
    full = addon.pipeline.compute(bpy.context)
    assert radiance(relit, "Square") == pytest.approx(radiance(full, "Square"), rel=1e-9)
