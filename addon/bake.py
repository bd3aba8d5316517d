"""Lightmaps and refined twins computed from a solution, off Blender's main thread (numpy only).

`outputs` reads each requested object's mesh into a `MeshData` on the main thread; `run` here
turns requests into results with the core solution (gathering through `sampling`), reporting
progress and honouring cancel; `outputs` writes them into the scene afterwards.
"""

from dataclasses import dataclass, field

import numpy as np

from . import adaptive_lightmap, refine, sampling, texels

# gutter rings around every UV chart
DILATION = 4


@dataclass
class MeshData:
    """A result mesh as plain arrays (read from Blender's evaluated mesh).

    Attributes
    ----------
    positions : ndarray, shape (V, 3)
        Object-local vertex positions.
    matrix : ndarray, shape (4, 4)
        World matrix.
    triangles : ndarray of int64, shape (T, 3)
        Vertex indices of the loop triangles.
    triangle_loops : ndarray of int64, shape (T, 3)
        Their loop (corner) indices.
    triangle_polygon : ndarray of int64, shape (T,)
    material_index : ndarray of int64, shape (F,)
        Per polygon.
    smooth : ndarray of bool, shape (F,)
        Per polygon.
    uv_layers : dict
        UV map name -> per-loop UVs, shape (L, 2).
    """

    positions: np.ndarray
    matrix: np.ndarray
    triangles: np.ndarray
    triangle_loops: np.ndarray
    triangle_polygon: np.ndarray
    material_index: np.ndarray
    smooth: np.ndarray
    uv_layers: dict

    def world_positions(self):
        M = self.matrix
        return self.positions @ M[:3, :3].T + M[:3, 3]

    def triangle_uv(self, name):
        """UVs of the triangles' corners in map `name`, shape (T, 3, 2)."""
        return self.uv_layers[name][self.triangle_loops]


@dataclass
class LightmapRequest:
    """A lightmap of one object: its mesh, the UV map to bake through and the image size.

    `tol` is the relative tolerance of `adaptive_lightmap.sample` (0: gather every texel).
    `pixels` (H, W, 4 RGBA, linear, alpha 1) is filled by `run`; `texels` is the number of
    texels covered (edge texels included), `gathered` how many of them were gathered.
    """

    target: str
    mesh: MeshData
    uv_name: str
    width: int
    height: int
    generated_uv: bool = False
    tol: float = adaptive_lightmap.DEFAULT_TOL
    pixels: np.ndarray = None
    texels: int = 0
    gathered: int = 0


@dataclass
class RefineRequest:
    """A refined twin of one object; `result` (refine.Refined, values front then back) is filled
    by `run`."""

    target: str
    mesh: MeshData
    tol: float
    min_edge: float
    max_edge: float = np.inf
    two_sided: bool = False
    result: object = None


@dataclass
class Requests:
    lightmaps: list = field(default_factory=list)
    refined: list = field(default_factory=list)

    def __bool__(self):
        return bool(self.lightmaps or self.refined)


def lightmap_pixels(request, sol, handles, surfaces, progress=None, cancel=None):
    """Bake one lightmap: rasterise the UV triangles, gather at the texels (adaptively, see
    `adaptive_lightmap`), dilate.

    Returns
    -------
    pixels : ndarray of float32, shape (H, W, 4)
        RGBA (alpha 1 on covered and dilated texels, 0 elsewhere).
    texels : int
        Texels covered.
    gathered : int
        Texels gathered (the others interpolated within `request.tol`).
    """
    mesh = request.mesh
    W, H = request.width, request.height
    texel, triangle, bary, _ = texels.rasterise(mesh.triangle_uv(request.uv_name), W, H)
    where = sampling.MeshSurfaces(mesh.world_positions(), mesh.triangles, surfaces, request.target)
    located = where.locate(triangle, bary)
    hit = np.flatnonzero(located.item >= 0)
    texel = texel[hit]
    located = sampling.Located(located.item[hit], located.u[hit], located.v[hit], located.x[hit])
    row = np.full(H * W, -1, np.int64)
    row[texel] = np.arange(texel.size)
    stage = f"lightmap {request.target}"
    done = [0]

    def evaluate(points):
        part = sampling.Located(located.item[points], located.u[points], located.v[points], located.x[points])

        def report(_, fraction):
            if progress is not None:
                # the adaptive sampler gathers a fraction of the texels it cannot know ahead
                progress(stage, min((done[0] + fraction * points.size) / max(texel.size, 1), 1.0))

        out = sampling.gather(sol, handles, part, "front", report, cancel, stage)
        done[0] += points.size
        return out

    if request.tol > 0:
        rgb, gathered = adaptive_lightmap.sample(row.reshape(H, W), located.item, evaluate, request.tol)
    else:
        rgb, gathered = evaluate(np.arange(texel.size)), np.ones(texel.size, bool)
    image = np.zeros((H * W, 3))
    covered = np.zeros(H * W, bool)
    image[texel] = rgb
    covered[texel] = True
    image, covered = texels.dilate(image.reshape(H, W, 3), covered.reshape(H, W), DILATION)
    pixels = np.zeros((H, W, 4), np.float32)
    pixels[..., :3] = image
    pixels[..., 3] = covered
    return pixels, int(texel.size), int(gathered.sum())


def refined_mesh(request, sol, handles, surfaces, progress=None, cancel=None):
    """Refine one object's mesh against the solution (values: front, then back if two-sided)."""
    mesh = request.mesh
    where = sampling.MeshSurfaces(mesh.world_positions(), mesh.triangles, surfaces, request.target)
    stage = f"refine {request.target}"

    def evaluate(triangle, bary):
        located = where.locate(triangle, bary)
        two = _two_sided_items(located, surfaces) if request.two_sided else None
        out = [sampling.gather(sol, handles, located, "front", None, cancel, stage)]
        if two is not None:
            sub = sampling.Located(np.where(two, located.item, -1), located.u, located.v, located.x)
            out.append(sampling.gather(sol, handles, sub, "back", None, cancel, stage))
        return np.concatenate(out, axis=1)

    def report(_, fraction):
        if progress is not None:
            progress(stage, fraction)

    return refine.refine(where, evaluate, request.tol, request.min_edge, request.max_edge, progress=report)


def _two_sided_items(located, surfaces):
    """True where the point's item is two-sided (has back results), shape (K,)."""
    flags = np.array([item.material.two_sided for item in surfaces] + [False])
    return flags[located.item]


def run(requests, sol, handles, surfaces, progress=None, cancel=None):
    """Fill every request's result (lightmap pixels, refined meshes)."""
    for request in requests.lightmaps:
        request.pixels, request.texels, request.gathered = lightmap_pixels(
            request, sol, handles, surfaces, progress, cancel
        )
    for request in requests.refined:
        request.result = refined_mesh(request, sol, handles, surfaces, progress, cancel)
