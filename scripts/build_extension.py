"""Build and validate the Blender extension zip: dist/curved_radiosity-<version>.zip.

Usage (from the repository root, with the dev venv):

    .venv/bin/python scripts/build_extension.py [--output-dir DIR] [--blender-ext PATH]

The repository keeps a single copy of the solver in core/; addon/core is a relative symlink to
it. Blender's packer skips symlinks, so this script stages addon/ into a temporary directory
with the symlink replaced by a real copy of core/ (Python files only), then runs Blender's own
extension tool, `blender_ext.py build` and `blender_ext.py validate`, found inside the bpy
package (bpy/<version>/scripts/addons_core/bl_pkg/cli/blender_ext.py) unless --blender-ext or
$BLENDER_EXT says otherwise. It runs under plain Python. The zip holds the core as the
subpackage curved_radiosity/core, so installing it adds no top-level `core` module.
"""

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ADDON = ROOT / "addon"
CORE = ROOT / "core"


def find_blender_ext():
    """Path of blender_ext.py shipped inside the installed bpy package."""
    override = os.environ.get("BLENDER_EXT")
    if override:
        return Path(override)
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("bpy is not installed here: pass --blender-ext PATH/TO/blender_ext.py")
    package = Path(next(iter(spec.submodule_search_locations)))
    found = sorted(package.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        sys.exit(f"blender_ext.py not found under {package}")
    return found[-1]


def valid_tags(blender_ext):
    """Blender's list of valid extension tags, next to the extension tool in the same bpy."""
    scripts = blender_ext.parents[3]
    tags = scripts / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    return str(tags) if tags.exists() else ""


def stage(directory):
    """Copy addon/ to `directory`, replacing the core symlink by the core's Python files."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "core")
    shutil.copytree(ADDON, directory, ignore=ignore)
    shutil.copytree(CORE, directory / "core", ignore=shutil.ignore_patterns("__pycache__", "*.pyc", ".*"))
    return directory


def build(output_dir, blender_ext):
    """Build, then validate, the extension; returns the zip's path."""
    manifest = tomllib.loads((ADDON / "blender_manifest.toml").read_text())
    output_dir.mkdir(parents=True, exist_ok=True)
    target = output_dir / f"{manifest['id']}-{manifest['version']}.zip"
    tags = valid_tags(blender_ext)
    with tempfile.TemporaryDirectory() as tmp:
        source = stage(Path(tmp) / manifest["id"])
        command = [sys.executable, str(blender_ext), "build", "--source-dir", str(source)]
        subprocess.run(command + ["--output-filepath", str(target), f"--valid-tags={tags}"], check=True)
    subprocess.run(
        [sys.executable, str(blender_ext), "validate", str(target), f"--valid-tags={tags}"], check=True
    )
    return target


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", type=Path, default=ROOT / "dist")
    parser.add_argument("--blender-ext", type=Path, default=None, help="path to Blender's blender_ext.py")
    args = parser.parse_args(argv)
    target = build(args.output_dir.resolve(), args.blender_ext or find_blender_ext())
    print(target)
    return 0


if __name__ == "__main__":
    sys.exit(main())
