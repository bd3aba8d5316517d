"""The extension zip: built by Blender's own tool, core bundled as a subpackage, installable."""

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from blender_helpers import MODULE, ROOT, bpy

pytestmark = pytest.mark.blender

INSTALL_AND_INSPECT = """
import os, sys, json
import bpy
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
import importlib
addon = importlib.import_module("bl_ext.user_default.curved_radiosity")
print(json.dumps(dict(
    top_level_core="core" in sys.modules,
    addon_file=addon.__file__,
    core_name=addon.core.__name__,
    core_file=addon.core.__file__,
    enabled="bl_ext.user_default.curved_radiosity" in bpy.context.preferences.addons,
    operator=hasattr(bpy.ops.curved_radiosity, "compute"),
)))
"""


POSIX_ONLY = ("resource", "fcntl", "termios", "pwd", "grp", "pty", "tty", "syslog")

# install without enabling, block the POSIX-only modules (as on Windows, where they do not
# exist), then enable and import the extension and light a plane with a point light
WITHOUT_POSIX_MODULES = """
import importlib, json, sys
import bpy
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=False)
blocked = sys.argv[2].split(",")
for name in blocked:
    sys.modules[name] = None
refused = []
for name in blocked:
    try:
        importlib.import_module(name)
    except ImportError:
        refused.append(name)
for name in [m for m in sys.modules if m.startswith("bl_ext.user_default.curved_radiosity")]:
    del sys.modules[name]
bpy.ops.preferences.addon_enable(module="bl_ext.user_default.curved_radiosity")
addon = importlib.import_module("bl_ext.user_default.curved_radiosity")
bpy.ops.mesh.primitive_plane_add(size=2)
plane = bpy.context.active_object
bpy.ops.object.light_add(type="POINT", location=(0, 0, 2))
bpy.context.active_object.data.energy = 100.0
bpy.context.scene.curved_radiosity.quality = "DRAFT"
result = bpy.ops.curved_radiosity.compute()
lit = addon.adapter.read_color_attribute(plane.data, "Radiosity")
print(json.dumps(dict(
    refused=refused,
    still_blocked=[name for name in blocked if sys.modules.get(name, 0) is None],
    core=addon.core.__name__,
    result=sorted(result),
    lit=float(lit[:, :3].min()),
)))
"""


def test_extension_runs_without_posix_only_modules(extension_zip, tmp_path):
    """The installed extension imports and computes where `resource`, `fcntl`, `termios`, `pwd`,
    ... cannot be imported (Windows): a fresh Blender with those modules blocked lights a plane."""
    env = {"BLENDER_USER_RESOURCES": str(tmp_path), "PATH": "/usr/bin:/bin"}
    done = subprocess.run(
        [sys.executable, "-c", WITHOUT_POSIX_MODULES, str(extension_zip), ",".join(POSIX_ONLY)],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=600,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    import json

    info = json.loads(done.stdout.strip().splitlines()[-1])
    assert info["refused"] == list(POSIX_ONLY)  # the block works: each import raised ImportError
    assert info["still_blocked"] == list(POSIX_ONLY)
    assert info["core"] == MODULE + ".core" and info["result"] == ["FINISHED"]
    assert info["lit"] > 0.0


def test_zip_name_and_contents(extension_zip):
    """Named from the manifest; core/*.py copied in as a subpackage; no symlink, cache or script."""
    manifest = tomllib.loads((ROOT / "addon" / "blender_manifest.toml").read_text())
    assert extension_zip.name == f"{manifest['id']}-{manifest['version']}.zip"
    assert manifest["id"] == "curved_radiosity" and manifest["schema_version"] == "1.0.0"
    assert manifest["blender_version_min"] == "5.0.0" and "permissions" not in manifest
    with zipfile.ZipFile(extension_zip) as archive:
        names = set(archive.namelist())
        core_files = {f"core/{p.name}" for p in (ROOT / "core").glob("*.py")}
        assert core_files <= names
        assert archive.read("core/__init__.py") == (ROOT / "core" / "__init__.py").read_bytes()
    assert {"__init__.py", "blender_manifest.toml", "adapter.py", "operators.py"} <= names
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
    assert "run_in_blender.py" not in names


def test_repository_keeps_one_core():
    """addon/core is a relative symlink to ../core, not a copy."""
    link = ROOT / "addon" / "core"
    assert link.is_symlink() and Path(link.readlink()) == Path("../core")


def test_fresh_session_installs_without_top_level_core(extension_zip, tmp_path):
    """In a new Python with its own user dir, the zip installs, enables, and adds no `core` module."""
    env = {"BLENDER_USER_RESOURCES": str(tmp_path), "PATH": "/usr/bin:/bin"}
    done = subprocess.run(
        [sys.executable, "-c", INSTALL_AND_INSPECT, str(extension_zip)],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    import json

    info = json.loads(done.stdout.strip().splitlines()[-1])
    assert not info["top_level_core"]
    assert info["enabled"] and info["operator"]
    assert info["core_name"] == MODULE + ".core"
    assert Path(info["addon_file"]).is_relative_to(tmp_path)
    assert Path(info["core_file"]).is_relative_to(tmp_path)


def test_installed_module_is_the_extension(addon):
    """Tests use the installed module: its core is the bundled copy, registered operators work."""
    assert addon.__name__ == MODULE
    assert addon.core.__name__ == MODULE + ".core"
    assert "user_default" in addon.__file__ and str(ROOT) not in addon.__file__
    for name in ("compute", "clear", "show"):
        assert hasattr(bpy.ops.curved_radiosity, name)
    for panel in ("VIEW3D_PT_curved_radiosity", "RENDER_PT_curved_radiosity"):
        assert hasattr(bpy.types, panel)
    assert bpy.types.VIEW3D_PT_curved_radiosity.bl_region_type == "UI"  # the N sidebar
    assert hasattr(bpy.types.Scene, "curved_radiosity")
    assert bpy.types.Object.bl_rna.properties["curved_radiosity_include"].default is True


def test_disable_and_enable_again(addon):
    """unregister() removes every class and property; register() brings them back."""
    bpy.ops.preferences.addon_disable(module=MODULE)
    assert not hasattr(bpy.types.Scene, "curved_radiosity")
    assert "curved_radiosity_include" not in bpy.types.Object.bl_rna.properties
    bpy.ops.preferences.addon_enable(module=MODULE)
    assert hasattr(bpy.types.Scene, "curved_radiosity")


def test_in_repo_headless_entry_point():
    """`python -m addon.headless --help` runs from the repository root (symlinked core)."""
    done = subprocess.run(
        [sys.executable, "-m", "addon.headless", "--help"], capture_output=True, text=True, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr
    assert "--render" in done.stdout and "--out" in done.stdout
