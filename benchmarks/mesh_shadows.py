"""Exact shadows of polygon meshes against sampled ones (issue 11): time and error per gathered point.

An emitting floor [-1, 1]^2 (E = 1, the only light), a ceiling at z = 2 (rho 0.5, 4 x 4 patches)
and between them a closed, concave mesh ball (three bumps around its axis; its non-planar quads
split into triangles as Blender does), solved at tol 1e-3 and gathered (`radiosity_at`) at six
ceiling points in and out of its shadow. Each mesh size is run twice in one process: with its
exact shadows (`occluded.MESH_PIECES` as shipped) and with rays (`MESH_PIECES = 0`: the path
meshes of more pieces take).

Reference: 0.5 F_vis(x -> floor) by randomised QMC with its own ray-triangle tests
(`tests/reference/occluded_mc.py`, 2^18 points x 8 shifts), with its standard error.

Run alone: python -m benchmarks.mesh_shadows [--sizes 6x3 8x4]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from reference.occluded_mc import point_factor  # noqa: E402
from test_mesh_shadows import bumpy_ball, emitting_floor_scene  # noqa: E402

import core  # noqa: E402
from core import occluded  # noqa: E402

U = np.array([0.2, 0.35, 0.5, 0.5, 0.65, 0.8])
V = np.array([0.5, 0.45, 0.5, 0.3, 0.55, 0.5])


def run(mesh, pieces):
    """(seconds, gathered B (6,), stats) with meshes of up to `pieces` pieces exact."""
    kept = occluded.MESH_PIECES
    occluded.MESH_PIECES = pieces
    try:
        scene, top, _ = emitting_floor_scene(mesh, patches=(4, 4))
        start = time.perf_counter()
        solution = scene.solve(tol=1e-3)
        B = solution.radiosity_at(top, U, V)[:, 0]
        return time.perf_counter() - start, B, solution.stats
    finally:
        occluded.MESH_PIECES = kept


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["6x3", "8x4"], help="ball grids nu x nv")
    args = parser.parse_args(argv)
    ceiling = core.Quad((-1, -1, 2), (-1, 1, 2), (1, 1, 2), (1, -1, 2))
    x, normal = ceiling.evaluate(U, V)
    normal = normal / np.linalg.norm(normal, axis=1)[:, None]
    print(
        "| pieces | shadows | solve + gather (s) | shadow lines | rays | max rel. error | mean rel. error |"
    )
    print("|---|---|---|---|---|---|---|")
    for size in args.sizes:
        nu, nv = (int(s) for s in size.split("x"))
        mesh = core.PolygonMesh(*bumpy_ball((0.1, 0.0, 1.0), 0.45, nu, nv), name=f"ball {size}")
        triangles = mesh.triangles()[0]
        reference = np.array(
            [
                point_factor(x[k], normal[k], ((-1, -1, 0), (2, 0, 0), (0, 2, 0)), triangles=triangles)
                for k in range(6)
            ]
        )
        B_ref, se = 0.5 * reference[:, 0], 0.5 * reference[:, 1]
        for label, pieces in (("rays", 0), ("exact", occluded.MESH_PIECES)):
            seconds, B, stats = run(mesh, pieces)
            error = np.abs(B - B_ref) / B_ref
            lines = stats.get("shadow_lines", 0) + stats.get("gather_shadow_lines", 0)
            rays = stats.get("rays", 0) + stats.get("gather_rays", 0)
            print(
                f"| {len(mesh.piece_corners)} | {label} | {seconds:.2f} | {lines} | {rays} | "
                f"{error.max():.1e} | {error.mean():.1e} |"
            )
        print(f"(reference standard error at most {np.max(se / B_ref):.1e} relative)")


if __name__ == "__main__":
    main()
