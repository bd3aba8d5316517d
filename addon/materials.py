"""Blender materials as diffuse reflectance and emitted radiance.

Read from the shader node tree feeding the active Cycles material output's Surface input:

- Principled BSDF: reflectance = Base Color; emission = Emission Color x Emission Strength;
- Diffuse BSDF: reflectance = Color;
- Emission: emission = Color x Strength (Cycles renders an Emission shader of strength S and
  colour C with radiance S C in W / (m^2 sr), as a mesh seen straight on shows);
- Add Shader sums both inputs; Mix Shader blends them by Fac.

Linked (textured) inputs use their unlinked default value, with a warning. No material, or a
node we do not know, gives the default grey 0.8, like Blender's default surface. What Cycles
renders but a diffuse solver cannot (`unsupported_features`: the Principled BSDF's specular
layer, metallic, transmission, subsurface, coat, sheen, thin film, alpha, diffuse roughness,
normal and bump maps; a Diffuse BSDF's roughness and normal; displacement) is reported in one
warning per material: the result is the diffuse part alone. Reflectance is
clamped to at most `MAX_REFLECTANCE` (radiosity needs < 1), with a warning. Backface culling on
the material makes the surface one-sided, otherwise it is two-sided, as Blender renders meshes.
"""

from dataclasses import dataclass, field

import numpy as np

DEFAULT_REFLECTANCE = 0.8
MAX_REFLECTANCE = 0.99


@dataclass
class MaterialSpec:
    """Radiometric properties of one material.

    Attributes
    ----------
    reflectance : ndarray, shape (3,)
        Diffuse reflectance (albedo) per RGB channel, in [0, MAX_REFLECTANCE].
    emission : ndarray, shape (3,)
        Emitted radiance, W / (m^2 sr) per channel.
    two_sided : bool
    warnings : list of str
    """

    reflectance: np.ndarray
    emission: np.ndarray
    two_sided: bool = True
    warnings: list = field(default_factory=list)


def default_spec():
    """The surface Blender renders without a material: grey 0.8, two-sided, no emission."""
    return MaterialSpec(np.full(3, DEFAULT_REFLECTANCE), np.zeros(3))


def material_spec(material):
    """The `MaterialSpec` of a bpy Material (or None for no material)."""
    if material is None:
        return default_spec()
    warnings = []
    output = _output_node(material)
    link = _surface_link(output)
    if link is None:
        if output is None:
            warnings.append(f"material {material.name!r} has no shader nodes: using its viewport colour")
            reflectance = np.array(material.diffuse_color[:3], dtype=np.float64)
        else:
            reflectance = np.zeros(3)
        emission = np.zeros(3)
    else:
        reflectance, emission = _shader(link.from_node, material.name, warnings)
        features = unsupported_features(link.from_node)
        displacement = output.inputs.get("Displacement")
        if displacement is not None and displacement.is_linked:
            features.append("displacement")
        if features:
            warnings.append(
                f"material {material.name!r}: Cycles renders {', '.join(features)}, which the radiosity "
                "solver leaves out (it keeps the diffuse part)"
            )
    if np.any(reflectance > MAX_REFLECTANCE):
        warnings.append(
            f"material {material.name!r}: reflectance {np.round(reflectance, 4).tolist()} clamped to "
            f"{MAX_REFLECTANCE} (radiosity needs reflectance below 1)"
        )
    reflectance = np.clip(reflectance, 0.0, MAX_REFLECTANCE)
    emission = np.maximum(emission, 0.0)
    return MaterialSpec(reflectance, emission, not material.use_backface_culling, warnings)


def _output_node(material):
    tree = material.node_tree
    if tree is None:
        return None
    output = tree.get_output_node("CYCLES")
    return output if output is not None else tree.get_output_node("ALL")


def _surface_link(output):
    if output is None:
        return None
    socket = output.inputs.get("Surface")
    return socket.links[0] if socket is not None and socket.is_linked else None


def _value(node, name, material_name, warnings):
    """An input's unlinked value as float64 RGB (shape (3,)) or scalar; `name` or input index."""
    socket = node.inputs[name]
    if socket.is_linked:
        warnings.append(
            f"material {material_name!r}: input {socket.name!r} of {node.name!r} is linked; "
            "using its default value"
        )
    value = socket.default_value
    return float(value) if isinstance(value, float) else np.array(value[:3], dtype=np.float64)


def _shader(node, material_name, warnings):
    """(reflectance (3,), emission (3,)) of a shader node, recursively through Add/Mix."""
    if node.type == "REROUTE":
        link = node.inputs[0].links[0] if node.inputs[0].is_linked else None
        return _shader(link.from_node, material_name, warnings) if link else (np.zeros(3), np.zeros(3))
    if node.type == "BSDF_PRINCIPLED":
        reflectance = _value(node, "Base Color", material_name, warnings)
        emission = _value(node, "Emission Color", material_name, warnings) * _value(
            node, "Emission Strength", material_name, warnings
        )
        return reflectance, emission
    if node.type == "BSDF_DIFFUSE":
        return _value(node, "Color", material_name, warnings), np.zeros(3)
    if node.type == "EMISSION":
        colour = _value(node, "Color", material_name, warnings)
        return np.zeros(3), colour * _value(node, "Strength", material_name, warnings)
    if node.type in ("ADD_SHADER", "MIX_SHADER"):
        nothing = (np.zeros(3), np.zeros(3))
        shaders = [s for s in node.inputs if s.type == "SHADER"]
        parts = [
            _shader(s.links[0].from_node, material_name, warnings) if s.is_linked else nothing
            for s in shaders
        ]
        if node.type == "ADD_SHADER":
            return parts[0][0] + parts[1][0], parts[0][1] + parts[1][1]
        f = _value(node, 0, material_name, warnings)  # "Fac" before Blender 5.0, "Factor" since
        return (1 - f) * parts[0][0] + f * parts[1][0], (1 - f) * parts[0][1] + f * parts[1][1]
    warnings.append(
        f"material {material_name!r}: shader node {node.name!r} ({node.type}) is not supported; "
        f"using grey {DEFAULT_REFLECTANCE}"
    )
    return np.full(3, DEFAULT_REFLECTANCE), np.zeros(3)


# Principled BSDF inputs whose nonzero value adds what a diffuse solver cannot represent:
# input name -> feature named in the report
PRINCIPLED_WEIGHTS = {
    "Metallic": "metallic",
    "Transmission Weight": "transmission",
    "Subsurface Weight": "subsurface scattering",
    "Coat Weight": "coat",
    "Sheen Weight": "sheen",
    "Thin Film Thickness": "thin film",
    "Diffuse Roughness": "diffuse roughness (Oren-Nayar)",
}
NORMAL_INPUTS = {"Normal": "a normal or bump map", "Coat Normal": "a coat normal map"}


def _scalar(node, name):
    """An input's default value as a float (None if the node has no such input)."""
    socket = node.inputs.get(name)
    return None if socket is None else float(socket.default_value)


def unsupported_features(node, seen=None):
    """What the shader tree under `node` renders beyond a diffuse reflectance and emission.

    Parameters
    ----------
    node : bpy ShaderNode
    seen : set, optional
        Nodes already visited (shared sub-trees are read once).

    Returns
    -------
    list of str
        Feature descriptions, each once, in tree order (empty: the solver represents it all).
    """
    seen = set() if seen is None else seen
    if node.as_pointer() in seen:
        return []
    seen.add(node.as_pointer())
    found = []
    if node.type == "BSDF_PRINCIPLED":
        level = _scalar(node, "Specular IOR Level")
        if level is not None and (level > 0 or node.inputs["Specular IOR Level"].is_linked):
            found.append(f"a specular layer (IOR {_scalar(node, 'IOR'):g}, Specular IOR Level {level:g})")
        for name, feature in PRINCIPLED_WEIGHTS.items():
            socket = node.inputs.get(name)
            if socket is not None and (socket.is_linked or float(socket.default_value) > 0):
                found.append(feature)
        alpha = node.inputs.get("Alpha")
        if alpha is not None and (alpha.is_linked or float(alpha.default_value) < 1):
            found.append("transparency (alpha)")
    if node.type == "BSDF_DIFFUSE":
        roughness = node.inputs.get("Roughness")
        if roughness is not None and (roughness.is_linked or float(roughness.default_value) > 0):
            found.append("diffuse roughness (Oren-Nayar)")
    if node.type in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE"):
        for name, feature in NORMAL_INPUTS.items():
            socket = node.inputs.get(name)
            if socket is not None and socket.is_linked:
                found.append(feature)
    if node.type == "EMISSION" or node.type == "BSDF_PRINCIPLED":
        colour = node.inputs.get("Emission Color" if node.type == "BSDF_PRINCIPLED" else "Color")
        strength = _scalar(node, "Emission Strength" if node.type == "BSDF_PRINCIPLED" else "Strength")
        if colour is not None and colour.is_linked and strength:
            found.append("an emission texture")
    for socket in node.inputs:
        if socket.type == "SHADER" and socket.is_linked:
            found += unsupported_features(socket.links[0].from_node, seen)
        elif node.type == "REROUTE" and socket.is_linked:
            found += unsupported_features(socket.links[0].from_node, seen)
    return list(dict.fromkeys(found))
