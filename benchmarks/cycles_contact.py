"""Cycles' radiance on a floor under a resting ball: the reference data of tests/test_hierarchy.py.

Run from the repository root (Blender as a Python module; not part of the test suite, ~3 min):

    .venv/bin/python -m benchmarks.cycles_contact [--samples 4096]

Scene (`tests/test_hierarchy.py::contact_scene` builds the same one in the core): a 4 m floor
(Diffuse BSDF 0.5) as a grid of 81 x 81 vertices (80 subdivisions, 0.05 m apart, so that
vertices lie on the sample points), a UV sphere of 128 x 64 segments, radius 0.5, shaded
smooth, resting on it at the origin (Diffuse BSDF 0.5), a 1 m square area light of 200 W 3 m up
at (0.4, 0.3), black world. Cycles bakes COMBINED (outgoing radiance) to the floor's vertex
colours with two seeds. Saved: the floor points at the radii RADII from the ball's foot along +x,
-x, +y and -y, and the two bakes' values there (their mean is the reference, half their
difference its noise), to
tests/data/cycles_contact.npz.
"""

import argparse
import sys
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.cycles_bake import bake_combined, black_world, diffuse_material  # noqa: E402

RADII = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.7, 1.0)
DIRECTIONS = ((1, 0), (-1, 0), (0, 1), (0, -1))


def build():
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=80, y_subdivisions=80, size=4.0)
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.materials.append(diffuse_material(bpy, "Floor", (0.5,) * 3))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=0.5, location=(0, 0, 0.5))
    bpy.ops.object.shade_smooth()
    bpy.context.active_object.data.materials.append(diffuse_material(bpy, "Ball", (0.5,) * 3))
    bpy.ops.object.light_add(type="AREA", location=(0.4, 0.3, 3.0))
    light = bpy.context.active_object
    light.data.energy = 200.0
    light.data.size = 1.0
    black_world(bpy)
    return floor


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4096)
    args = parser.parse_args(argv)
    floor = build()
    P = np.array([v.co[:] for v in floor.data.vertices])
    points = np.array([(r * dx, r * dy, 0.0) for r in RADII for dx, dy in DIRECTIONS])
    index = np.array([np.argmin(np.linalg.norm(P - p, axis=1)) for p in points])
    assert np.abs(P[index] - points).max() < 1e-5, "grid vertices are not on the sample points"
    first = bake_combined(bpy, [floor], args.samples, seed=0)["Floor"][index]
    second = bake_combined(bpy, [floor], args.samples, seed=1)["Floor"][index]
    out = ROOT / "tests" / "data" / "cycles_contact.npz"
    np.savez(
        out, points=points, first=first, second=second, samples=args.samples, blender=bpy.app.version_string
    )
    mean = 0.5 * (first + second)[:, 0].reshape(len(RADII), -1).mean(1)
    noise = 0.5 * np.abs(first - second)[:, 0].reshape(len(RADII), -1).mean(1)
    for r, m, n in zip(RADII, mean, noise):
        print(f"r = {r:.2f} m: {m:.5f} +- {n:.5f}")
    print(f"saved {out}")


if __name__ == "__main__":
    main()
