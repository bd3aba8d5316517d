"""Blender lights in the radiometric units of the core, following Cycles.

Sources (Blender source tree):

- intern/cycles/blender/light.cpp, `BlenderSync::sync_light`: strength = colour (times the
  blackbody colour when `use_temperature`) x energy x 2^exposure; spot size/blend and area
  size/shape are passed through; a light shines along its object's local -Z axis.
- intern/cycles/scene/light.cpp, `LightManager::device_update_lights`: an area light's area is
  |size_x axis_u| |size_y axis_v| (the object's scale included), times pi / 4 for DISK and
  ELLIPSE; with `normalize` (the default) the strength is divided by that area.
- Checked by rendering with Cycles in tests/blender/test_lights.py: an area light of power P
  and area A has radiance P / (pi A) (P / pi without `normalize`); a point or spot light of
  power P has intensity P / (4 pi) W/sr (a spot's cone cuts it, never concentrates it); a sun
  of strength E gives irradiance E W/m^2 on a plane facing it.
"""

from dataclasses import dataclass

import numpy as np

from .core import Disk, Quad


@dataclass
class LightSpec:
    """A point, spot or sun light for `core.Scene.add_*_light`.

    Attributes
    ----------
    name : str
    kind : {"point", "spot", "sun"}
    params : dict
        Keyword arguments of `Scene.add_point_light` / `add_spot_light` / `add_sun_light`.
    """

    name: str
    kind: str
    params: dict


def light_power(color, energy, exposure=0.0, temperature_color=None):
    """Cycles' light strength: colour x (blackbody colour) x energy x 2^exposure, shape (3,)."""
    rgb = np.asarray(color, dtype=np.float64)[:3]
    if temperature_color is not None:
        rgb = rgb * np.asarray(temperature_color, dtype=np.float64)[:3]
    return rgb * float(energy) * 2.0 ** float(exposure)


def area_radiance(power, area, normalize=True):
    """Radiance (W / (m^2 sr)) of an area light of `power` (W, shape (3,)) and `area` (m^2)."""
    return np.asarray(power, dtype=np.float64) / (np.pi * (area if normalize else 1.0))


def point_intensity(power):
    """Radiant intensity (W/sr) of a point or spot light of `power` (W, shape (3,))."""
    return np.asarray(power, dtype=np.float64) / (4.0 * np.pi)


def area_surface(shape, size_x, size_y, world_from_local):
    """The emitting surface of an area light, front along the light's local -Z, in world space.

    Parameters
    ----------
    shape : {"SQUARE", "RECTANGLE", "DISK", "ELLIPSE"}
    size_x, size_y : float
        `size` and `size_y` (size_y is ignored for SQUARE and DISK).
    world_from_local : ndarray, shape (4, 4)

    Returns
    -------
    core.Quad or core.Disk (transformed)
    """
    a = 0.5 * float(size_x)
    b = 0.5 * float(size_y if shape in ("RECTANGLE", "ELLIPSE") else size_x)
    if shape in ("DISK", "ELLIPSE"):
        # unit disk facing -Z, stretched to semi-axes a, b, then placed in the world
        local = np.diag([a, b, 1.0, 1.0])
        return Disk((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 1.0).transformed(world_from_local @ local)
    # u along +Y, v along +X: (p10 - p00) x (p01 - p00) points along -Z
    quad = Quad((-a, -b, 0.0), (-a, b, 0.0), (a, b, 0.0), (a, -b, 0.0))
    return quad.transformed(world_from_local)


def _power(light):
    temperature = light.temperature_color if getattr(light, "use_temperature", False) else None
    return light_power(light.color, light.energy, getattr(light, "exposure", 0.0), temperature)


def area_emitter(obj, M):
    """(surface, radiance (3,), warnings) for an AREA light object with world matrix M (4, 4)."""
    light = obj.data
    surface = area_surface(light.shape, light.size, light.size_y, M)
    radiance = area_radiance(_power(light), surface.area(), getattr(light, "normalize", True))
    warnings = []
    if light.spread < np.pi - 1e-6:
        warnings.append(f"area light {obj.name!r}: spread below 180 degrees is treated as 180")
    return surface, radiance, warnings


def light_spec(obj, M):
    """(LightSpec, warnings) for a POINT, SPOT or SUN light object with world matrix M (4, 4)."""
    light = obj.data
    position = M[:3, 3]
    forward = -M[:3, 2] / np.linalg.norm(M[:3, 2])
    power = _power(light)
    if light.type == "SUN":
        return LightSpec(obj.name, "sun", dict(direction=forward, irradiance=power)), []
    params = dict(position=position, intensity=point_intensity(power), radius=float(light.shadow_soft_size))
    if light.type == "POINT":
        return LightSpec(obj.name, "point", params), []
    warnings = []
    if light.use_square:
        warnings.append(f"spot light {obj.name!r}: square spots are not supported (treated as round)")
    params.update(direction=forward, spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
    return LightSpec(obj.name, "spot", params), warnings
