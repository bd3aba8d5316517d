"""core/ is Blender-free: it imports with numpy alone and never touches bpy, mathutils or bmesh."""

import ast
import subprocess
import sys
from pathlib import Path

CORE = Path(__file__).resolve().parents[1] / "core"
BLENDER_MODULES = {"bpy", "mathutils", "bmesh", "gpu", "bl_ui"}


def test_core_imports_without_blender():
    """Import core in a fresh interpreter in which importing bpy fails."""
    code = (
        "import sys\n"
        "for name in ('bpy', 'mathutils', 'bmesh'): sys.modules[name] = None\n"
        "import core\n"
        "square = core.Quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0))\n"
        "assert core.form_factor(core.Sphere((0, 0, 6), 1), square) > 0\n"
        "assert not {'bpy', 'mathutils', 'bmesh'} & {m for m in sys.modules if sys.modules[m] is not None}\n"
    )
    subprocess.run([sys.executable, "-c", code], cwd=CORE.parent, check=True)


POSIX_ONLY = ("resource", "fcntl", "termios", "pwd", "grp", "posix", "pty", "tty", "syslog")


def test_core_imports_without_posix_only_modules():
    """Import core and solve a small scene in an interpreter where POSIX-only modules cannot be
    imported (as on Windows, where `resource` does not exist)."""
    code = (
        "import sys\n"
        f"for name in {POSIX_ONLY!r}: sys.modules[name] = None\n"
        "import core\n"
        "scene = core.Scene()\n"
        "scene.add(core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), reflectance=0.5)\n"
        "scene.add(core.Disk((0.5, 0.5, 1), (0, 0, -1), 0.2), emission=1.0)\n"
        "solution = scene.solve(tol=1e-2)\n"
        "assert solution.stats['peak_rss_bytes'] is None\n"
        "assert solution.radiosity(0).max() > 0\n"
    )
    subprocess.run([sys.executable, "-c", code], cwd=CORE.parent, check=True)


def test_no_blender_import_statement_in_core():
    """No module in core/ names a Blender module in an import statement, even lazily."""
    for path in CORE.rglob("*.py"):
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            for name in names:
                assert name.split(".")[0] not in BLENDER_MODULES, f"{path.name} imports {name}"
