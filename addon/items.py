"""What the Blender scene becomes before it meets the core: plain data, no bpy."""

from dataclasses import dataclass, field

import numpy as np

from .materials import MaterialSpec


@dataclass
class SurfaceItem:
    """One core surface with its material and where its radiance is written back.

    Attributes
    ----------
    name : str
        Unique within the scene, e.g. "Cube[3]" for polygon piece 3 of object "Cube".
    surface : core.Surface
        In world coordinates.
    material : MaterialSpec
    patches : (int, int) or None
        Patch grid for `core.Scene.add`, None for automatic.
    occluder : bool
    target : str or None
        Name of the `Target` that receives this surface's radiance (None for area lights).
    vertices : ndarray of int, shape (K,)
        Target mesh vertex of each sample point.
    params : ndarray, shape (K, 2)
        (u, v) of each sample point on `surface`.
    """

    name: str
    surface: object
    material: MaterialSpec
    patches: tuple = None
    occluder: bool = True
    target: str = None
    vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    params: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


@dataclass
class Target:
    """A Blender object whose mesh (or mesh twin) gets the `Radiosity` attribute.

    Attributes
    ----------
    name : str
        Object name.
    n_vertices : int
        Vertex count of the mesh that receives the attribute.
    twin : bool
        True if the result goes to a mesh twin built from Blender's evaluated geometry (NURBS
        surfaces, meshes with modifiers or shared mesh data), False for the object's own mesh.
    two_sided : bool
        True if any of its surfaces is two-sided (then a back-side attribute is written too).
    """

    name: str
    n_vertices: int
    twin: bool
    two_sided: bool = False


@dataclass
class Collected:
    """The whole scene: surfaces, point/spot/sun lights, result targets and messages.

    `skipped` names each object left out (with the reason); those messages are in `warnings` too.
    `sky` is the world's uniform sky radiance (W / (m^2 sr), shape (3,)).
    """

    surfaces: list = field(default_factory=list)
    lights: list = field(default_factory=list)
    targets: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    sky: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def has_emitters(self):
        """True if any light has power, any surface emits or the world gives light."""
        lit = [
            np.max(light.params.get("intensity", light.params.get("irradiance", 0.0)))
            for light in self.lights
        ]
        glowing = [np.max(s.material.emission) for s in self.surfaces]
        return any(p > 0.0 for p in lit + glowing + [np.max(self.sky)])
