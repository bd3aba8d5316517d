"""Curved-patch radiosity core: parametric surfaces and error-controlled form factors (numpy only)."""

from .primitives import Cylinder, Disk, Quad, Sphere
from .surface import Surface

__all__ = ["Cylinder", "Disk", "Quad", "Sphere", "Surface"]
