"""The command line: `python -m addon.headless` and the `blender -b ... --python` script.

Both run in a subprocess from the repository root (the in-repo package with its symlinked core),
on a copy of the seed scene, and must write the lit .blend and a Cycles PNG.
"""

import importlib
import re
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


def headless(*args, cwd=ROOT):
    """Run `python -m addon.headless ARGS` from the repository root (stdout is a pipe)."""
    command = [sys.executable, "-m", "addon.headless", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, cwd=cwd, timeout=600)


def check_progress(stdout):
    """Progress in a pipe: whole lines only, each naming its stage with that stage's own
    percentage, which never goes back within a stage (a second pass has its own label)."""
    assert "\r" not in stdout
    lines = re.findall(r"^  (\S.*?)\s+(\d+\.\d)%$", stdout, flags=re.MULTILINE)
    assert len(lines) >= 4, stdout
    finished, current, last = set(), None, -1.0
    for label, percent in lines:
        percent = float(percent)
        if label != current:
            assert label not in finished, f"stage {label!r} appears to restart:\n{stdout}"
            if current is not None:
                finished.add(current)
            current, last = label, -1.0
        assert percent >= last, f"stage {label!r} went back from {last} to {percent}:\n{stdout}"
        last = percent
    assert "gather" in {label for label, _ in lines}


def check_outputs(done, lit, image):
    assert done.returncode == 0, done.stdout + done.stderr
    check_progress(done.stdout)
    assert "stage times" in done.stdout and "solve" in done.stdout
    assert lit.exists() and image.exists() and image.stat().st_size > 0
    bpy.ops.wm.open_mainfile(filepath=str(lit))
    for name in ("Square", "Emitter"):
        assert "Radiosity" in bpy.data.objects[name].data.color_attributes
    loaded = bpy.data.images.load(str(image))
    assert tuple(loaded.size) == (64, 48)


def test_python_module_entry_point(tmp_path):
    scene = shutil.copy(SEED, tmp_path / "seed.blend")
    lit, image = tmp_path / "new" / "lit.blend", tmp_path / "images" / "lit.png"  # folders made as needed
    command = [sys.executable, "-m", "addon.headless", str(scene), "--out", str(lit), "--render", str(image)]
    options = ["--quality", "DRAFT", "--samples", "2", "--resolution", "64", "48"]
    done = subprocess.run(command + options, capture_output=True, text=True, cwd=ROOT, timeout=600)
    check_outputs(done, lit, image)


def test_blender_python_script(tmp_path):
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


def one_line_error(done, code, *words):
    """Exit code `code`, and stderr is one "error: ..." line containing `words`, no traceback."""
    assert done.returncode == code, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), done.stderr
    assert "Traceback" not in done.stdout + done.stderr
    for word in words:
        assert word in lines[0], done.stderr


def test_errors_exit_non_zero(tmp_path):
    """A scene with nothing to light: exit code 1 and the reason on stderr."""
    empty = tmp_path / "empty.blend"
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(empty), copy=True)
    one_line_error(headless(empty), 1, "nothing to light")


def test_help_lists_the_exit_codes(addon):
    """--help documents every exit code the command uses (the installed module's table)."""
    done = headless("--help")
    assert done.returncode == 0, done.stderr
    assert "exit codes:" in done.stdout
    codes = importlib.import_module(addon.__name__ + ".headless").EXIT_CODES
    for code, text in codes.items():
        assert re.search(rf"^  {code}\s+{re.escape(text[:30])}", done.stdout, flags=re.MULTILINE), code


@pytest.mark.parametrize("case", ["missing", "text file", "renamed text file", "folder"])
def test_unreadable_scene_is_a_one_line_error(tmp_path, case):
    """A missing or non-.blend scene file: exit code 3 and one line naming the file."""
    path = {
        "missing": tmp_path / "nowhere.blend",
        "text file": tmp_path / "notes.txt",
        "renamed text file": tmp_path / "notes.blend",
        "folder": tmp_path,
    }[case]
    if case in ("text file", "renamed text file"):
        path.write_text("not a scene")
    one_line_error(headless(path), 3, str(path))


@pytest.mark.parametrize(
    "option",
    [
        ["--tol", "-1"],
        ["--tol", "nan"],
        ["--samples", "0"],
        ["--max-bounces", "-2"],
        ["--resolution", "0", "4"],
        ["--method", "fast"],
    ],
)
def test_bad_options_exit_with_the_usage_code(tmp_path, option):
    """Out-of-range options: exit code 2 and an argparse message naming the option, no traceback."""
    scene = shutil.copy(SEED, tmp_path / "seed.blend")
    done = headless(scene, *option)
    assert done.returncode == 2 and option[0] in done.stderr and "Traceback" not in done.stderr


def test_unwritable_output_is_a_one_line_error(tmp_path):
    """--out under a path whose parent is a file: exit code 4, the output path named."""
    scene = shutil.copy(SEED, tmp_path / "seed.blend")
    blocker = tmp_path / "file"
    blocker.write_text("")
    one_line_error(headless(scene, "--quality", "DRAFT", "--out", blocker / "lit.blend"), 4, "lit.blend")


def test_zero_scale_object_is_skipped_by_name(tmp_path):
    """An object scaled to zero: skipped with one stderr warning naming it and its zero scale,
    the rest lit (exit code 0)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=4)
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0, 0, 2))
    bpy.context.active_object.name = "Squashed"
    bpy.context.active_object.scale = (0.0, 0.0, 0.0)
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 3))
    path = tmp_path / "zero.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    done = headless(path, "--quality", "DRAFT")
    assert done.returncode == 0, done.stderr
    (line,) = [line for line in done.stderr.splitlines() if "'Squashed'" in line]
    assert line.startswith("warning: ") and "scale is zero" in line and "skipped" in line


def test_console_progress_on_a_terminal_and_in_a_pipe(addon):
    """A terminal gets a bar redrawn with \\r and a newline per stage; a pipe gets plain lines;
    a stage run again is labelled as its second pass in both."""
    import io

    calls = [("form factors", 0.0), ("form factors", 0.5), ("form factors", 1.0), ("visibility", 0.0)]
    calls += [("visibility", 1.0), ("form factors", 0.0), ("form factors", 1.0)]
    for terminal in (True, False):
        stream = io.StringIO()
        printer = addon.console.ConsoleProgress(stream, terminal=terminal)
        for stage, fraction in calls:
            printer(stage, fraction)
        printer.close()
        text = stream.getvalue()
        assert ("\r" in text) == terminal
        assert "form factors (pass 2)" in text and text.endswith("100.0%\n")
        if not terminal:
            check_plain = [line.split()[-1] for line in text.splitlines()]
            assert check_plain == ["0.0%", "50.0%", "100.0%", "0.0%", "100.0%", "0.0%", "100.0%"]


def test_method_chooses_the_solver(tmp_path):
    """`--method hierarchical` solves on the hierarchy (its stats say so) and writes the results."""
    scene = shutil.copy(SEED, tmp_path / "seed.blend")
    lit = tmp_path / "lit.blend"
    done = headless(scene, "--quality", "DRAFT", "--method", "hierarchical", "--out", lit)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "solver hierarchical" in done.stdout and "links" in done.stdout
    bpy.ops.wm.open_mainfile(filepath=str(lit))
    assert "Radiosity" in bpy.data.objects["Square"].data.color_attributes
