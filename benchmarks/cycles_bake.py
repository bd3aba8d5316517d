"""Cycles COMBINED bakes to vertex colours: the outgoing radiance Cycles gives each vertex.

A COMBINED bake to a colour attribute stores, per vertex, emission + rho E / pi for a diffuse
surface (E its irradiance, direct and indirect): the quantity the add-on writes as `Radiosity`.
Used by tests/blender (small checks against Cycles) and `benchmarks.cycles_agreement`. Needs
bpy (Blender as a module); nothing in core/ or addon/ imports it.
"""

import time

import numpy as np

BAKE_ATTRIBUTE = "Cycles Bake"
MAX_SAMPLES = 1 << 20  # per bake point (Cycles takes up to 2^24)
NOISE_MARGIN = 1.2  # on the sample count a measured noise asks for (the measure is noisy too)


def prepare_cycles(scene, samples, seed=0, bounces=64):
    """CPU Cycles without denoising, clamping or caustics filters, `samples` per pixel."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = int(samples)
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.seed = int(seed)
    scene.cycles.max_bounces = scene.cycles.diffuse_bounces = int(bounces)
    scene.cycles.sample_clamp_direct = scene.cycles.sample_clamp_indirect = 0.0
    scene.cycles.use_light_tree = True
    scene.cycles.blur_glossy = 0.0


def bake_combined(bpy, objects, samples, seed=0):
    """Bake Cycles COMBINED to a POINT colour attribute of each mesh object in `objects`.

    Parameters
    ----------
    bpy : module
    objects : list of bpy Object (meshes, in the current scene)
    samples : int
        Samples per bake point.
    seed : int

    Returns
    -------
    dict
        Object name -> outgoing radiance per vertex of its mesh, shape (V, 3).
    """
    scene = bpy.context.scene
    prepare_cycles(scene, samples, seed)
    bake = scene.render.bake
    bake.target = "VERTEX_COLORS"
    bake.use_clear = True
    bake.use_selected_to_active = False
    out = {}
    for obj in objects:
        mesh = obj.data
        if BAKE_ATTRIBUTE not in mesh.color_attributes:
            mesh.color_attributes.new(BAKE_ATTRIBUTE, "FLOAT_COLOR", "POINT")
        mesh.color_attributes.active_color = mesh.color_attributes[BAKE_ATTRIBUTE]
    bpy.ops.object.select_all(action="DESELECT")
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    bpy.ops.object.bake(type="COMBINED", target="VERTEX_COLORS")
    for obj in objects:
        attribute = obj.data.color_attributes[BAKE_ATTRIBUTE]
        rgba = np.empty(len(attribute.data) * 4, np.float32)
        attribute.data.foreach_get("color", rgba)
        out[obj.name] = rgba.reshape(-1, 4)[:, :3].astype(np.float64)
        obj.data.color_attributes.remove(attribute)
    return out


def bake_noise(first, second):
    """The rms noise of the mean of two bakes (different seeds) relative to its mean level, over
    channel sums (shapes (V, 3))."""
    b, c = (np.asarray(v, dtype=np.float64).sum(1) for v in (first, second))
    level = max(float(np.abs(0.5 * (b + c)).mean()), 1e-300) if b.size else 1.0
    return float(np.sqrt(np.mean(0.25 * (b - c) ** 2))) / level if b.size else 0.0


def converged_bakes(bpy, objects, samples, noise, budget, max_samples=MAX_SAMPLES):
    """Two bakes (seeds 0 and 1) of each object in `objects`, each at the sample count that
    brings the noise of their mean (`bake_noise`) to `noise`, within a time budget.

    All objects are baked first at `samples`. An object noisier than `noise` wants N (measured
    / noise)^2 x NOISE_MARGIN samples, at most `max_samples`. Those objects are baked again (the
    rest of the scene still lights and shadows them) in groups, each at its largest member's
    count, with the members wanting at least half of it (a bake call re-syncs the scene: example
    05 has 144 balls), the count cut to what `budget` seconds buy for the group at the first
    bake's time per corner and sample (Cycles bakes a vertex colour per face corner; that rate
    includes the bake's fixed cost, so it errs on the safe side).

    Returns
    -------
    first, second : dict
        Object name -> per-vertex radiance, shape (V, 3).
    counts : dict
        Object name -> the samples its bakes took.
    seconds : float
        The first bake's time at `samples` (all objects).
    """
    start = time.perf_counter()
    first = bake_combined(bpy, objects, samples, seed=0)
    seconds = time.perf_counter() - start
    second = bake_combined(bpy, objects, samples, seed=1)
    corners = {o.name: max(len(o.data.loops), 1) for o in objects}
    rate = seconds / (samples * sum(corners.values()))  # s per corner and sample
    counts = {o.name: samples for o in objects}
    wanted = {}
    for obj in objects:
        measured = bake_noise(first[obj.name], second[obj.name])
        if measured > noise:
            wanted[obj.name] = min(samples * (measured / noise) ** 2 * NOISE_MARGIN, max_samples)
    queue = sorted((o for o in objects if o.name in wanted), key=lambda o: -wanted[o.name])
    while queue:
        top = wanted[queue[0].name]
        group = [o for o in queue if wanted[o.name] >= 0.5 * top]
        queue = queue[len(group) :]
        more = int(min(top, budget / (rate * sum(corners[o.name] for o in group))))
        if more <= samples:
            continue
        for seed, bakes in enumerate((first, second)):
            bakes.update(bake_combined(bpy, group, more, seed=seed))
        counts.update({o.name: more for o in group})
    return first, second, counts, seconds


def diffuse_material(bpy, name, colour, emission=(0.0, 0.0, 0.0)):
    """A material of a Diffuse BSDF (plus an Emission shader when `emission` > 0): what the solver
    represents exactly (a Principled BSDF adds a specular layer the solver leaves out)."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*colour, 1.0)
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    shader = diffuse.outputs[0]
    if max(emission) > 0:
        glow = tree.nodes.new("ShaderNodeEmission")
        glow.inputs["Color"].default_value = (*emission, 1.0)
        glow.inputs["Strength"].default_value = 1.0
        add = tree.nodes.new("ShaderNodeAddShader")
        tree.links.new(diffuse.outputs[0], add.inputs[0])
        tree.links.new(glow.outputs[0], add.inputs[1])
        shader = add.outputs[0]
    tree.links.new(shader, output.inputs["Surface"])
    return mat


def agreement(ours, first, second, mask=None):
    """Compare per-vertex radiance with two Cycles bakes (different seeds), over channel sums.

    Parameters
    ----------
    ours, first, second : ndarray, shape (V, 3)
    mask : ndarray of bool, shape (V,), optional
        Vertices to compare (default all).

    Returns
    -------
    dict
        "rms" (of ours minus the bakes' mean, net of the mean's noise), "bias" (mean
        difference), "worst" (largest |difference| beyond 3 noise sigmas), "noise" (rms noise of
        the mean of the two bakes), all relative to the bakes' mean level; "vertices".
    """
    sel = np.ones(len(ours), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    a, b, c = (np.asarray(v, dtype=np.float64)[sel].sum(1) for v in (ours, first, second))
    if a.size == 0:
        return dict(rms=np.nan, bias=np.nan, worst=np.nan, noise=np.nan, vertices=0)
    mean = 0.5 * (b + c)
    level = max(float(np.abs(mean).mean()), 1e-300)
    noise = bake_noise(np.asarray(first)[sel], np.asarray(second)[sel]) * level  # (absolute)
    d = a - mean
    rms = np.sqrt(max(float(np.mean(d * d)) - noise**2, 0.0))
    worst = float(np.max(np.maximum(np.abs(d) - 3.0 * noise, 0.0)))
    return dict(
        rms=rms / level,
        bias=float(d.mean()) / level,
        worst=worst / level,
        noise=noise / level,
        vertices=int(a.size),
    )


def black_world(bpy):
    """Give the scene a world whose Background is black. (`world.color` is not what Cycles
    renders: a new world's node tree has a Background of 0.05 grey, which once added
    0.5 x 0.05 = 0.025 W/(m^2 sr) to every texel of a Cycles bake that the add-on, seeing no
    world, did not have.)"""
    world = bpy.data.worlds.new("Black")
    if world.node_tree is None:  # Blender < 5.0
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bpy.context.scene.world = world
    return world


def bake_image(bpy, obj, size, samples, seed=0, uv="UVMap"):
    """Bake Cycles COMBINED of mesh object `obj` into a float image through UV map `uv`.

    Parameters
    ----------
    bpy : module
    obj : bpy Object
        Its first material receives a temporary image node (removed after).
    size : int
        Texels per side.
    samples : int
    seed : int
    uv : str

    Returns
    -------
    pixels : ndarray, shape (size, size, 3)
        Outgoing radiance per texel, rows along v.
    seconds : float
        The bake's time.
    """
    prepare_cycles(bpy.context.scene, samples, seed)
    image = bpy.data.images.new(f"cycles {seed}", size, size, float_buffer=True, alpha=True)
    tree = obj.data.materials[0].node_tree
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    tree.nodes.active = node
    for other in bpy.context.view_layer.objects:
        other.select_set(other == obj)
    bpy.context.view_layer.objects.active = obj
    start = time.perf_counter()
    bpy.ops.object.bake(type="COMBINED", target="IMAGE_TEXTURES", uv_layer=uv, margin=2)
    seconds = time.perf_counter() - start
    tree.nodes.remove(node)
    pixels = np.empty(size * size * 4, np.float32)
    image.pixels.foreach_get(pixels)
    bpy.data.images.remove(image)
    return pixels.reshape(size, size, 4)[..., :3].astype(np.float64), seconds


PROBE_LIFT = 1e-5  # of the probe size plus the point's largest coordinate: its height above the surface


def probe_object(bpy, name, points, normals, inward, size, materials, material_index=None):
    """A mesh of small triangles for baking Cycles' radiance at chosen surface points.

    A vertex bake shades a mesh vertex at the vertex itself; to ask for the value at any point of
    a surface (a point 1 mm inside a face next to a seam: the limit from that face, which a
    vertex on the seam may not give, since that vertex also lies in the other face's plane), each
    probe is a triangle in the surface's tangent plane whose first vertex is the point (lifted
    along the normal by PROBE_LIFT x (size + its largest coordinate), well above float32's
    spacing there: a probe exactly in the surface would be shadowed by it), reaching `size`
    toward `inward`. It has the surface's
    material and is visible to camera rays only: no other ray meets it, so it neither shadows
    nor lights anything (Cycles bakes nothing on an object with no ray visibility at all).

    Parameters
    ----------
    bpy : module
    name : str
    points, normals, inward : ndarray, shape (K, 3)
        Points, unit front normals and a direction along the surface away from the seam.
    size : float
        Probe size (m).
    materials : list of bpy Material
    material_index : ndarray of int, shape (K,), optional

    Returns
    -------
    bpy Object
        Linked to the scene; bake it with `bake_combined` and read every third vertex.
    """
    points, normals, inward = (np.asarray(a, np.float64).reshape(-1, 3) for a in (points, normals, inward))
    d = inward - (inward * normals).sum(1)[:, None] * normals
    d /= np.linalg.norm(d, axis=1)[:, None]
    t = np.cross(normals, d)
    # lifted by more than float32's spacing at the point (Cycles' geometry is float32)
    lift = PROBE_LIFT * (size + np.abs(points).max(1))
    p = points + lift[:, None] * normals
    # counter-clockwise about the normal: the triangle's front is the surface's
    coords = np.stack([p, p + size * (d - 0.5 * t), p + size * (d + 0.5 * t)], 1).reshape(-1, 3)
    faces = np.arange(coords.shape[0]).reshape(-1, 3)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(c) for c in coords], [], [tuple(f) for f in faces])
    for material in materials:
        mesh.materials.append(material)
    if material_index is not None:
        mesh.polygons.foreach_set("material_index", np.asarray(material_index, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    for flag in ("diffuse", "glossy", "transmission", "volume_scatter", "shadow"):
        setattr(obj, f"visible_{flag}", False)
    bpy.context.scene.collection.objects.link(obj)
    return obj
