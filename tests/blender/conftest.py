"""Blender tests run against the BUILT extension, installed into a fresh user directory.

`BLENDER_USER_RESOURCES` must name a temporary folder before bpy is first imported (Blender
fixes its extension repositories at start-up), so it is set here, at collection time. pytest
collects tests/blender before the test_*.py files next to it; if bpy was imported earlier
anyway (e.g. `pytest tests/test_nurbs_blender.py tests/blender`), these tests skip and ask to be
run on their own. The session fixture `addon` builds dist zip with scripts/build_extension.py,
installs it with `bpy.ops.extensions.package_install_files` and returns the installed module
`bl_ext.user_default.curved_radiosity`; tests use that module, never the repository's `addon`.
"""

import importlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MODULE = "bl_ext.user_default.curved_radiosity"
USER_RESOURCES = tempfile.mkdtemp(prefix="curved-radiosity-user-")
FRESH = "bpy" not in sys.modules
if FRESH:
    os.environ["BLENDER_USER_RESOURCES"] = USER_RESOURCES

try:
    import bpy
except ImportError:  # the whole directory then skips
    bpy = None


def pytest_sessionfinish(session):
    shutil.rmtree(USER_RESOURCES, ignore_errors=True)


def build_zip(output_dir):
    """Run scripts/build_extension.py; returns the zip's path."""
    command = [sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--output-dir", str(output_dir)]
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    return Path(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory):
    return build_zip(tmp_path_factory.mktemp("dist"))


@pytest.fixture(scope="session")
def addon(extension_zip):
    """The installed extension module (installed once per session)."""
    if bpy is None:
        pytest.skip("bpy is not installed")
    if not FRESH:
        pytest.skip("bpy was imported before tests/blender/conftest.py: run tests/blender in its own process")
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.extensions.package_install_files(
        filepath=str(extension_zip), repo="user_default", enable_on_install=True
    )
    return importlib.import_module(MODULE)


@pytest.fixture(autouse=True)
def empty_scene(request):
    """A fresh empty scene for each test, with the add-on enabled (other tests may reset prefs)."""
    if "addon" not in request.fixturenames:
        yield
        return
    if MODULE not in bpy.context.preferences.addons:
        bpy.ops.preferences.addon_enable(module=MODULE)
    bpy.ops.wm.read_homefile(use_empty=True)
    yield
