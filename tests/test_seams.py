"""Seams: points where surfaces touch get the limit from their visible side.

Blender stores coordinates as float32 (relative spacing 6e-8), so a wall standing on a floor
has its foot a few 1e-8 m above or below the floor's plane. A gathered point on the wall's
bottom edge that stays within that distance of the edge lies behind the floor, which then hides
a light above it (the 19-36 % dark lines of issue 15). The reference is the direct light's closed
form, B = rho I cos(theta) / (pi d^2): nothing else lights the wall (the other surfaces are black).
"""

import numpy as np
import pytest

import core

RHO = 0.5
INTENSITY = 2.0
LIGHT = np.array([0.5, 0.5, 0.6])


def direct(x, n):
    """Radiosity of a diffuse point (rho RHO) lit by the point light alone, shape (K,)."""
    toward = LIGHT - x
    d = np.linalg.norm(toward, axis=-1)
    return RHO * INTENSITY * np.einsum("ki,ki->k", toward, n) / d**3 / np.pi


def wall_faces(bottom, top, rows):
    """A wall at x = 0 (front +x) from z = bottom to z = top, as `rows` faces, the way a Blender
    grid mesh becomes one flat quad per face."""
    z = np.linspace(bottom, top, rows + 1)
    return [core.Quad((0, 0, z[k]), (0, 1, z[k]), (0, 1, z[k + 1]), (0, 0, z[k + 1])) for k in range(rows)]


@pytest.mark.parametrize("offset", [-6e-8, -2e-8, 0.0, 3e-8])
def test_wall_foot_on_a_floor(offset):
    """The wall's bottom edge, `offset` off the floor's plane (float32 rounding), is lit as the
    limit from above: the floor does not hide the light from it."""
    scene = core.Scene()
    scene.add(core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), reflectance=0.0, patches=2)
    faces = wall_faces(offset, 1.0, 5)
    handles = [scene.add(face, reflectance=RHO, patches=1) for face in faces]
    scene.add_point_light(LIGHT, INTENSITY)
    sol = scene.solve(tol=1e-4)
    y = np.array([0.1, 0.5, 0.9])
    got = sol.radiosity_at(handles[0], y, np.zeros(3))[:, 0]
    x = np.stack([np.zeros(3), y, np.full(3, offset)], axis=1)
    expected = direct(x, np.tile([1.0, 0.0, 0.0], (3, 1)))
    assert np.allclose(got, expected, rtol=1e-4), (got, expected)


@pytest.mark.parametrize("offset", [-4e-8, 4e-8])
def test_wall_top_under_a_ceiling(offset):
    """The same at a wall-ceiling corner (the light below the ceiling, the wall's top edge a few
    1e-8 m above or below the ceiling's plane)."""
    scene = core.Scene()
    height = 1.0
    ceiling = core.Quad((0, 0, height), (0, 1, height), (1, 1, height), (1, 0, height))  # front -z
    scene.add(ceiling, reflectance=0.0, patches=2)
    faces = wall_faces(0.0, height + offset, 5)
    handles = [scene.add(face, reflectance=RHO, patches=1) for face in faces]
    scene.add_point_light(LIGHT, INTENSITY)
    sol = scene.solve(tol=1e-4)
    y = np.array([0.2, 0.5])
    got = sol.radiosity_at(handles[-1], y, np.ones(2))[:, 0]
    x = np.stack([np.zeros(2), y, np.full(2, height + offset)], axis=1)
    expected = direct(x, np.tile([1.0, 0.0, 0.0], (2, 1)))
    assert np.allclose(got, expected, rtol=1e-4), (got, expected)
