"""The built extension installed into a throw-away Blender user directory, for benchmarks.

Import this module before anything imports bpy: Blender fixes its extension repositories when
bpy is first imported, so `BLENDER_USER_RESOURCES` is set here first (as tests/blender/conftest.py
does for the tests).
"""

import importlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODULE = "bl_ext.user_default.curved_radiosity"
USER_RESOURCES = tempfile.mkdtemp(prefix="curved-radiosity-bench-")
if "bpy" in sys.modules:
    raise ImportError("import benchmarks.blender_addon before bpy (Blender fixes its folders at start-up)")
os.environ["BLENDER_USER_RESOURCES"] = USER_RESOURCES

import bpy  # noqa: E402 (after BLENDER_USER_RESOURCES)


def install_addon():
    """Build dist zip with scripts/build_extension.py, install and enable it; returns the module."""
    out = tempfile.mkdtemp(prefix="curved-radiosity-dist-")
    command = [sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--output-dir", out]
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(done.stdout + done.stderr)
    zip_path = done.stdout.strip().splitlines()[-1]
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    return importlib.import_module(MODULE)
