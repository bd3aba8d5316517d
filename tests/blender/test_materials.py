"""Materials as reflectance and emitted radiance (addon/materials.py)."""

import numpy as np
import pytest
from blender_helpers import bpy, material

pytestmark = pytest.mark.blender


def spec(addon, mat):
    return addon.materials.material_spec(mat)


def shader_material(name, *nodes):
    """A material whose output is fed by `nodes[0]` (bl_idname, {input: value}) [+ Mix/Add inputs]."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    made = []
    for idname, values in nodes:
        node = tree.nodes.new(idname)
        for key, value in values.items():
            node.inputs[key].default_value = value
        made.append(node)
    tree.links.new(made[0].outputs[0], output.inputs["Surface"])
    shader_inputs = [s for s in made[0].inputs if s.type == "SHADER"]
    for socket, node in zip(shader_inputs, made[1:]):
        tree.links.new(node.outputs[0], socket)
    return mat


def test_no_material_is_blender_default_grey(addon):
    """No material: reflectance 0.8 (Blender's default surface), two-sided, no emission."""
    s = spec(addon, None)
    assert s.reflectance.tolist() == [0.8, 0.8, 0.8] and not s.emission.any() and s.two_sided


def test_principled_base_colour_and_emission(addon):
    """Principled: Base Color -> reflectance, Emission Color x Strength -> radiance."""
    s = spec(addon, material("P", base=(0.2, 0.4, 0.6), emission=(1.0, 0.5, 0.0), strength=3.0))
    assert s.reflectance == pytest.approx([0.2, 0.4, 0.6])
    assert s.emission == pytest.approx([3.0, 1.5, 0.0])
    assert s.two_sided and s.warnings == [
        "material 'P': Cycles renders a specular layer (IOR 1.5, Specular IOR Level 0.5), which the "
        "radiosity solver leaves out (it keeps the diffuse part)"
    ]


def test_backface_culling_makes_one_sided(addon):
    assert not spec(addon, material("C", culling=True)).two_sided


def test_diffuse_and_emission_shaders(addon):
    """Diffuse BSDF Color -> reflectance; Emission Color x Strength -> radiance (reflectance 0)."""
    diffuse = spec(addon, shader_material("D", ("ShaderNodeBsdfDiffuse", {"Color": (0.3, 0.2, 0.1, 1.0)})))
    assert diffuse.reflectance == pytest.approx([0.3, 0.2, 0.1]) and not diffuse.emission.any()
    light = spec(
        addon, shader_material("E", ("ShaderNodeEmission", {"Color": (1, 0.5, 0.5, 1), "Strength": 4.0}))
    )
    assert light.emission == pytest.approx([4.0, 2.0, 2.0]) and not light.reflectance.any()


def test_add_and_mix_shaders(addon):
    """Add sums; Mix blends by its factor."""
    diffuse = ("ShaderNodeBsdfDiffuse", {"Color": (0.4, 0.4, 0.4, 1.0)})
    emission = ("ShaderNodeEmission", {"Color": (1, 1, 1, 1), "Strength": 2.0})
    added = spec(addon, shader_material("A", ("ShaderNodeAddShader", {}), diffuse, emission))
    assert added.reflectance == pytest.approx([0.4] * 3) and added.emission == pytest.approx([2.0] * 3)
    mixed = spec(addon, shader_material("M", ("ShaderNodeMixShader", {0: 0.25}), diffuse, emission))
    assert mixed.reflectance == pytest.approx([0.3] * 3) and mixed.emission == pytest.approx([0.5] * 3)


def test_reflectance_is_clamped_below_one_with_a_warning(addon):
    s = spec(addon, material("White", base=(1.0, 1.0, 0.5)))
    assert s.reflectance.max() < 1.0 and s.reflectance[2] == pytest.approx(0.5)
    assert any("clamped" in w for w in s.warnings)


def test_textures_and_unknown_shaders_warn(addon):
    """A linked Base Color uses its default value; an unknown shader gives grey 0.8; both warn."""
    mat = material("Tex", base=(0.1, 0.2, 0.3))
    tree = mat.node_tree
    noise = tree.nodes.new("ShaderNodeTexNoise")
    tree.links.new(noise.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    textured = spec(addon, mat)
    assert textured.reflectance == pytest.approx([0.1, 0.2, 0.3]) and any(
        "linked" in w for w in textured.warnings
    )
    glass = spec(addon, shader_material("G", ("ShaderNodeBsdfGlass", {})))
    assert np.allclose(glass.reflectance, 0.8) and any("not supported" in w for w in glass.warnings)


def feature_warnings(spec_):
    return [w for w in spec_.warnings if "leaves out" in w]


def test_principled_features_are_reported_once(addon):
    """Everything Cycles renders beyond diffuse + emission is named, in one warning per material:
    the default Principled BSDF's specular layer; metallic, transmission, subsurface, coat, sheen,
    alpha and a normal map when set; nothing for a Principled BSDF without specular."""
    plain = material("Plain")
    (warning,) = feature_warnings(spec(addon, plain))
    assert "'Plain'" in warning and "specular layer" in warning and "IOR 1.5" in warning
    bsdf = plain.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    assert feature_warnings(spec(addon, plain)) == []
    rich = material("Rich")
    bsdf = rich.node_tree.nodes["Principled BSDF"]
    values = {
        "Metallic": 1.0,
        "Transmission Weight": 0.5,
        "Subsurface Weight": 0.2,
        "Coat Weight": 0.3,
        "Sheen Weight": 0.4,
        "Alpha": 0.5,
    }
    for name, value in values.items():
        bsdf.inputs[name].default_value = value
    bump = rich.node_tree.nodes.new("ShaderNodeBump")
    rich.node_tree.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    (warning,) = feature_warnings(spec(addon, rich))
    for feature in ("specular", "metallic", "transmission", "subsurface", "coat", "sheen", "alpha", "normal"):
        assert feature in warning, (feature, warning)


def test_diffuse_roughness_emission_texture_and_displacement_are_reported(addon):
    """A rough Diffuse BSDF (Oren-Nayar), a textured emission and a displacement output are named;
    a plain Diffuse BSDF or Emission shader gives no report."""
    assert feature_warnings(spec(addon, shader_material("D", ("ShaderNodeBsdfDiffuse", {})))) == []
    rough = shader_material("Rough", ("ShaderNodeBsdfDiffuse", {"Roughness": 0.5}))
    (warning,) = feature_warnings(spec(addon, rough))
    assert "Oren-Nayar" in warning
    glow = shader_material("Glow", ("ShaderNodeEmission", {"Strength": 2.0}))
    assert feature_warnings(spec(addon, glow)) == []
    tree = glow.node_tree
    texture = tree.nodes.new("ShaderNodeTexNoise")
    tree.links.new(texture.outputs["Color"], tree.nodes["Emission"].inputs["Color"])
    displacement = tree.nodes.new("ShaderNodeDisplacement")
    tree.links.new(displacement.outputs[0], tree.nodes["Material Output"].inputs["Displacement"])
    (warning,) = feature_warnings(spec(addon, glow))
    assert "emission texture" in warning and "displacement" in warning


def test_a_shared_material_is_reported_once_per_run(addon):
    """Two objects sharing one Principled material: one feature warning in the collected run."""
    shared = material("Shared")
    for x in (0.0, 3.0):
        bpy.ops.mesh.primitive_plane_add(location=(x, 0.0, 0.0))
        bpy.context.active_object.data.materials.append(shared)
    bpy.context.view_layer.update()
    collected = addon.collect.collect(
        bpy.context.scene, bpy.context.view_layer, bpy.context.evaluated_depsgraph_get()
    )
    assert sum("'Shared'" in w and "leaves out" in w for w in collected.warnings) == 1
