"""The command line: `python -m addon.headless` and the `blender -b ... --python` script.

Both run in a subprocess from the repository root (the in-repo package with its symlinked core),
on a copy of the seed scene, and must write the lit .blend and a Cycles PNG.
"""

import shutil
import subprocess
import sys

import pytest
from blender_helpers import ROOT, bpy

pytestmark = pytest.mark.blender

SEED = ROOT / "blender_scenes" / "01_seed_sphere_over_square.blend"

# what `blender -b SCENE --python addon/run_in_blender.py -- ARGS` does, with bpy as a module
AS_BLENDER = """
import sys, runpy
import bpy
scene, script, args = sys.argv[1], sys.argv[2], sys.argv[3:]
bpy.ops.wm.open_mainfile(filepath=scene)
sys.argv = ["blender", "-b", scene, "--python", script, "--"] + args
runpy.run_path(script, run_name="__main__")
"""


@pytest.fixture
def solver(addon):
    if not hasattr(addon.core, "Scene"):
        pytest.skip("core.Scene is not available yet")
    return addon


def check_outputs(done, lit, image):
    assert done.returncode == 0, done.stdout + done.stderr
    assert "stage times" in done.stdout and "solve" in done.stdout
    assert lit.exists() and image.exists() and image.stat().st_size > 0
    bpy.ops.wm.open_mainfile(filepath=str(lit))
    for name in ("Square", "Emitter"):
        assert "Radiosity" in bpy.data.objects[name].data.color_attributes
    loaded = bpy.data.images.load(str(image))
    assert tuple(loaded.size) == (64, 48)


def test_python_module_entry_point(solver, tmp_path):
    scene = shutil.copy(SEED, tmp_path / "seed.blend")
    lit, image = tmp_path / "new" / "lit.blend", tmp_path / "images" / "lit.png"  # folders made as needed
    command = [sys.executable, "-m", "addon.headless", str(scene), "--out", str(lit), "--render", str(image)]
    options = ["--quality", "DRAFT", "--samples", "2", "--resolution", "64", "48"]
    done = subprocess.run(command + options, capture_output=True, text=True, cwd=ROOT, timeout=600)
    check_outputs(done, lit, image)


def test_blender_python_script(solver, tmp_path):
    scene = shutil.copy(SEED, tmp_path / "seed.blend")
    lit, image = tmp_path / "lit.blend", tmp_path / "lit.png"
    script = ROOT / "addon" / "run_in_blender.py"
    args = ["--out", str(lit), "--render", str(image), "--samples", "2", "--resolution", "64", "48"]
    done = subprocess.run(
        [sys.executable, "-c", AS_BLENDER, str(scene), str(script)] + args,
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=600,
    )
    check_outputs(done, lit, image)


def test_errors_exit_non_zero(tmp_path):
    """A scene with nothing to light: exit code 1 and the reason on stderr (no core.Scene needed)."""
    empty = tmp_path / "empty.blend"
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(empty), copy=True)
    done = subprocess.run(
        [sys.executable, "-m", "addon.headless", str(empty)], capture_output=True, text=True, cwd=ROOT
    )
    assert done.returncode == 1 and "nothing to light" in done.stderr
