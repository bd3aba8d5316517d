"""Cycles' radiance next to the seams of a closed box: the reference data of tests/test_light_levels.py.

Run from the repository root (Blender as a Python module; not part of the test suite, ~2 min):

    .venv/bin/python -m benchmarks.cycles_seams [--samples 4096]

Scene (`tests/test_light_levels.py::seam_box` builds the same one in the core): a closed 2 m box
(x, y in [-1, 1], z in [0, 2]; Blender's cube with its normals flipped inward, Diffuse BSDF 0.7),
a 0.6 m square area light of 40 W at (0, 0, 1.98) facing down (2 cm under the ceiling, so the
walls' tops are lit at grazing angles and the strip above the lamp's plane not at all), black
world. Probes (`cycles_bake.probe_object`: small triangles that no ray meets) at the distances
DISTANCES from a seam along LINES: the ceiling and the floor toward the back wall, the back wall
toward the ceiling and the floor, and the ceiling and back wall toward the corner (1, 1, 2).
Cycles bakes COMBINED (outgoing radiance) to the probes twice (seeds 0 and 1); saved: the points,
their normals and the two bakes (their mean is the reference, half their difference its
noise), to tests/data/cycles_seams.npz.
"""

import argparse
import sys
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.cycles_bake import bake_combined, black_world, diffuse_material, probe_object  # noqa: E402

DISTANCES = (0.001, 0.005, 0.02, 0.05, 0.1, 0.2, 0.4)
PROBE_SIZE = 1e-3
# (name, point at distance d, normal, direction away from the seam)
LINES = (
    ("ceiling to back wall", lambda d: (0.0, 1.0 - d, 2.0), (0, 0, -1), (0, -1, 0)),
    ("back wall to ceiling", lambda d: (0.0, 1.0, 2.0 - d), (0, -1, 0), (0, 0, -1)),
    ("back wall to floor", lambda d: (0.0, 1.0, d), (0, -1, 0), (0, 0, 1)),
    ("floor to back wall", lambda d: (0.0, 1.0 - d, 0.0), (0, 0, 1), (0, -1, 0)),
    ("ceiling to corner", lambda d: (1.0 - d, 1.0 - d, 2.0), (0, 0, -1), (-1, -1, 0)),
    ("back wall to corner", lambda d: (1.0 - d, 1.0, 2.0 - d), (0, -1, 0), (-1, 0, -1)),
)


def probes():
    """(points, normals, inward), each shape (len(LINES) * len(DISTANCES), 3), line by line."""
    rows = [(line(d), n, a) for _, line, n, a in LINES for d in DISTANCES]
    return tuple(np.array([r[k] for r in rows], dtype=np.float64) for k in range(3))


def build():
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.0, 0.0, 1.0))
    box = bpy.context.active_object
    box.name = "Box"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.flip_normals()
    bpy.ops.object.mode_set(mode="OBJECT")
    walls = diffuse_material(bpy, "Walls", (0.7, 0.7, 0.7))
    box.data.materials.append(walls)
    light = bpy.data.lights.new("Lamp", "AREA")
    light.size, light.energy = 0.6, 40.0
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = (0.0, 0.0, 1.98)
    bpy.context.scene.collection.objects.link(lamp)
    black_world(bpy)
    return walls


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4096)
    args = parser.parse_args(argv)
    walls = build()
    points, normals, inward = probes()
    probe = probe_object(bpy, "Probes", points, normals, inward, PROBE_SIZE, [walls])
    first = bake_combined(bpy, [probe], args.samples, seed=0)["Probes"][0::3]
    second = bake_combined(bpy, [probe], args.samples, seed=1)["Probes"][0::3]
    out = ROOT / "tests" / "data" / "cycles_seams.npz"
    np.savez(
        out,
        points=points,
        normals=normals,
        first=first,
        second=second,
        samples=args.samples,
        blender=bpy.app.version_string,
    )
    mean, noise = 0.5 * (first + second)[:, 0], 0.5 * np.abs(first - second)[:, 0]
    for k, (name, *_) in enumerate(LINES):
        rows = slice(k * len(DISTANCES), (k + 1) * len(DISTANCES))
        values = ", ".join(f"{d:g}: {m:.4f}+-{n:.4f}" for d, m, n in zip(DISTANCES, mean[rows], noise[rows]))
        print(f"{name}: {values}")
    print(f"saved {out}")


if __name__ == "__main__":
    main()
