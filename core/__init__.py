"""Curved-patch radiosity core (numpy only): parametric surfaces, form factors, radiosity scenes."""

from .formfactor import (
    AccuracyWarning,
    FormFactorEstimate,
    FormFactorSolver,
    form_factor,
    form_factor_estimate,
    form_factors,
)
from .gathered import GatherFactors
from .mesh import PolygonMesh
from .nurbs import NurbsSurface
from .primitives import Cylinder, Disk, Quad, Sphere
from .runner import Cancelled
from .scene import Scene
from .solution import Solution
from .solvers import ConvergenceError, CrossingSurfaceError
from .surface import Surface

__all__ = [
    "AccuracyWarning",
    "FormFactorEstimate",
    "FormFactorSolver",
    "form_factor",
    "form_factor_estimate",
    "form_factors",
    "GatherFactors",
    "Cylinder",
    "Disk",
    "NurbsSurface",
    "PolygonMesh",
    "Quad",
    "Sphere",
    "Surface",
    "Cancelled",
    "ConvergenceError",
    "CrossingSurfaceError",
    "Scene",
    "Solution",
]
