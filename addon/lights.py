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
- A point or spot light's `shadow_soft_size` is the radius of a sphere light and a sun's `angle`
  its angular diameter (`core.lights`); tests/blender/test_lights.py compares penumbrae with Cycles.
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
        params = dict(direction=forward, irradiance=power, angle=float(light.angle))
        return LightSpec(obj.name, "sun", params), []
    params = dict(
        position=position,
        intensity=point_intensity(power),
        radius=float(light.shadow_soft_size),
        soft_falloff=bool(getattr(light, "use_soft_falloff", False)),
    )
    if light.type == "POINT":
        return LightSpec(obj.name, "point", params), []
    warnings = []
    if light.use_square:
        warnings.append(f"spot light {obj.name!r}: square spots are not supported (treated as round)")
    params.update(direction=forward, spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
    return LightSpec(obj.name, "spot", params), warnings


def equirect_average(pixels):
    """Solid-angle mean of an equirectangular (latitude-longitude) image, shape (3,).

    pixels : ndarray, shape (H, W, C >= 3); row 0 at the bottom (Blender's order), the rows
    spanning latitudes -90 ... 90 degrees: each row weighs cos(latitude) (its share of the sphere).
    """
    H = pixels.shape[0]
    latitude = (np.arange(H) + 0.5) / H * np.pi - 0.5 * np.pi
    weight = np.cos(latitude)
    rows = pixels[..., :3].astype(np.float64).mean(1)  # (H, 3)
    return (weight[:, None] * rows).sum(0) / weight.sum()


def _image_average(image):
    """Solid-angle mean of an environment image (equirectangular), shape (3,)."""
    width, height = image.size
    if width * height == 0:
        raise ValueError(f"image {image.name!r} has no pixels")
    pixels = np.empty(width * height * image.channels, np.float32)
    image.pixels.foreach_get(pixels)
    return equirect_average(pixels.reshape(height, width, image.channels))


def world_sky(world):
    """(radiance (3,), warnings) of the uniform sky standing in for a Blender world.

    Cycles renders a world's Background shader of colour C and strength S as radiance C S
    (W / (m^2 sr)) from every direction; without shader nodes it uses `world.color`. A colour
    linked to an Environment Texture is replaced by its image's solid-angle average; a colour
    linked to anything else by the socket's default value; both with a warning naming what was
    averaged or replaced. Only the light's total reaches the solver: the sky is uniform.
    """
    if world is None:
        return np.zeros(3), []
    tree = world.node_tree
    output = tree.get_output_node("CYCLES") if tree is not None else None
    if output is None and tree is not None:
        output = tree.get_output_node("ALL")
    if output is None:
        return np.array(world.color[:3], dtype=np.float64), []
    surface = output.inputs.get("Surface")
    if surface is None or not surface.is_linked:
        return np.zeros(3), []
    node = surface.links[0].from_node
    warnings = []
    if node.type != "BACKGROUND":
        warnings.append(
            f"world {world.name!r}: shader {node.name!r} ({node.type}) is not supported; "
            "the world gives no light"
        )
        return np.zeros(3), warnings
    colour_socket, strength_socket = node.inputs["Color"], node.inputs["Strength"]
    colour = np.array(colour_socket.default_value[:3], dtype=np.float64)
    if colour_socket.is_linked:
        source = colour_socket.links[0].from_node
        image = getattr(source, "image", None) if source.type == "TEX_ENVIRONMENT" else None
        if image is not None and getattr(source, "projection", "EQUIRECTANGULAR") == "EQUIRECTANGULAR":
            colour = _image_average(image)
            warnings.append(
                f"world {world.name!r}: environment image {image.name!r} averaged to a uniform sky "
                f"{np.round(colour, 4).tolist()}"
            )
        else:
            warnings.append(
                f"world {world.name!r}: the background colour comes from {source.name!r} ({source.type}), "
                f"which cannot be averaged; using the socket's colour {np.round(colour, 4).tolist()}"
            )
    strength = float(strength_socket.default_value)
    if strength_socket.is_linked:
        warnings.append(
            f"world {world.name!r}: the background strength is linked; using its default value {strength}"
        )
    return np.maximum(colour * strength, 0.0), warnings
