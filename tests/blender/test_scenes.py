"""The example scenes in blender_scenes/: each loads and maps onto the expected core surfaces."""

import subprocess
import sys
from collections import Counter

import pytest
from blender_helpers import ROOT, bpy, collect

pytestmark = pytest.mark.blender

SCENES = ROOT / "blender_scenes"

# surface classes (area lights are Quads; each mesh that is not a UV sphere is one PolygonMesh per
# material), point/spot/sun lights, targets with twins
EXPECTED = {
    "01_seed_sphere_over_square": ({"Sphere": 1, "PolygonMesh": 1}, 0, 0),
    "02_sphere_in_cube": ({"Sphere": 1, "PolygonMesh": 1, "Quad": 1}, 0, 0),
    "03_cornell_box": ({"Sphere": 2, "PolygonMesh": 5, "Quad": 1, "NurbsSurface": 1}, 0, 1),
    "04_nurbs_only": ({"NurbsSurface": 6, "Quad": 1}, 0, 6),
    "05_stress_many_spheres": ({"Sphere": 144, "PolygonMesh": 1, "Quad": 1}, 1, 0),
}


def inventory(addon):
    collected = collect(addon)
    kinds = Counter(type(item.surface).__name__ for item in collected.surfaces)
    twins = sum(target.twin for target in collected.targets.values())
    return dict(kinds), len(collected.lights), twins, collected


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_scene_maps_onto_core_surfaces(addon, name):
    """Curved objects stay curved (spheres, NURBS), there is an emitter and a camera."""
    bpy.ops.wm.open_mainfile(filepath=str(SCENES / f"{name}.blend"))
    kinds, lights, twins, collected = inventory(addon)
    assert (kinds, lights, twins) == EXPECTED[name]
    assert collected.has_emitters() and not collected.warnings
    assert bpy.context.scene.camera is not None


def test_build_script_reproduces_the_scenes(addon, tmp_path):
    """blender_scenes/build_scenes.py rebuilds files with the same objects as the committed ones."""
    done = subprocess.run(
        [sys.executable, str(SCENES / "build_scenes.py"), "--out-dir", str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr
    for name in EXPECTED:
        contents = []
        for folder in (SCENES, tmp_path):
            bpy.ops.wm.open_mainfile(filepath=str(folder / f"{name}.blend"))
            contents.append(
                sorted((o.name, o.type, tuple(round(c, 5) for c in o.location)) for o in bpy.data.objects)
            )
        assert contents[0] == contents[1], name
