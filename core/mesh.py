"""A polygon mesh as one scene surface: Blender's faces (triangles, quads, n-gons) as flat pieces.

Faces are given as Blender stores them (`loop_starts`, `loop_totals`, `corner_verts`) or as a list
of vertex-index lists, corners in counter-clockwise order seen from the front (the right-hand
rule of Blender's face normal). Each face becomes flat pieces, each a `core.Quad` (a triangle is
a quad with p01 = p00), so that every piece has the exact flat inner integral (the POLYGON kind
of `core.inner`) and the exact segment test:

- a triangle is one piece;
- a quad is one piece if its corners lie on one plane (within PLANAR_RTOL of its size, which
  absorbs Blender's float32 rounding: the corners are then projected onto that plane) and it is
  convex; otherwise it is split into the triangles (0, 1, 2) and (0, 2, 3), as Blender's own
  loop triangles split a quad, so a non-planar quad is lit as it renders;
- an n-gon (n >= 5) is fan-split from corner 0 into triangles if it is planar and convex, and
  otherwise ear-clipped in its Newell plane (Eberly, "Triangulation by ear clipping", Geometric
  Tools, 2002): concave n-gons keep their shape;
- a face whose area is zero (to 1e-12 of its size squared) is skipped, with one warning that
  names the mesh and the face indices.

The face normal is Newell's (the vector area), see M. E. Newell, R. G. Newell and T. L.
Sancha, "A solution to the hidden surface problem", Proc. ACM Annual Conference, 1972.

`PolygonMesh.merge_coplanar` gives the same surface with each region of coplanar faces as one
polygon (a subdivided floor as one quad), so that its patches follow its size, not its faces.

Scene results of a mesh (`Scene.add(mesh, patches=(nu, nv))` splits every piece into nu x nv
patches): `Solution.radiosity(h)` per face in face order (the area-weighted mean over its patches),
`Solution.radiosity_at(h, faces, points)` at points on given faces, `Solution.vertex_radiosity(h)`
per vertex. In occlusion queries the mesh is one occluder whose faces are triangles of one
`bvh.BVH` (built once per mesh and kept by it).
"""

import warnings

import numpy as np

from . import checks, ragged
from .primitives import Quad

PLANAR_RTOL = 1e-6  # corners within this of the face plane (relative to the face size) are planar
DEGENERATE_RTOL = 1e-12  # vector area below this times the size squared: a face with no area
MAX_HULL_PLANES = 64  # distinct face planes a mesh may have to be tried as a convex room
HULL_RTOL = 1e-5  # ... pieces within this (of the mesh's size) of one plane share it
COPLANAR_RTOL = 1e-5  # faces within this (of the mesh's size) of one plane merge (`merge_coplanar`)
MERGED_CORNERS = 64  # most corners of a merged face that is not convex (ear clipping is quadratic)
MAX_SPLIT_PLANES = 256  # planes a chained region of faces is split into, at most (`merge_coplanar`)
ALONE_PLANES = 8  # ... and no more after this many in a row that hold one face each


class PolygonMesh:
    """A polygon mesh: vertices and faces (triangles, quads, n-gons), one surface of a scene.

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
        Vertex positions (m).
    faces : sequence of sequences of int, optional
        Vertex indices of each face (at least 3), counter-clockwise seen from the front.
    loop_starts, loop_totals : array_like of int, shape (F,), optional
    corner_verts : array_like of int, shape (L,), optional
        Blender's layout instead of `faces`: face f has the corners
        corner_verts[loop_starts[f] : loop_starts[f] + loop_totals[f]].
    two_sided : bool, optional
        Both sides reflect and emit (as Blender's faces do); `Scene.add` then adds back sides.
    name : str, optional
        Used in warnings and errors.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3)
    loop_starts, loop_totals, corner_verts : ndarray of int
    face_normal : ndarray, shape (F, 3)
        Unit Newell normals (zero for skipped faces).
    face_area : ndarray, shape (F,)
        Areas (m^2) of the faces' pieces (0 for skipped faces).
    skipped : ndarray of int
        Faces with no area, left out.
    piece_corners : ndarray, shape (P, 4, 3)
        Corners p00, p10, p11, p01 of the flat pieces (triangles repeat p00 as p01).
    piece_vertices : ndarray of int, shape (P, 4)
    piece_face : ndarray of int, shape (P,)
        Face of each piece, non-decreasing.

    Raises
    ------
    ValueError
        If vertices are not finite (V, 3) coordinates, a face has fewer than 3 corners or an
        index outside 0 .. V - 1, both or neither of `faces` and Blender's arrays are given, or
        no face has an area.
    """

    def __init__(
        self,
        vertices,
        faces=None,
        *,
        loop_starts=None,
        loop_totals=None,
        corner_verts=None,
        two_sided=False,
        name=None,
    ):
        if name is not None and not isinstance(name, str):
            raise checks.ArgumentTypeError(f"PolygonMesh name must be a str or None, got {name!r}")
        self.name = name
        label = self._label()
        V = checks.finite_array(vertices, f"{label} vertices")
        if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] < 3:
            raise ValueError(f"{label} vertices must have shape (V, 3) with V >= 3, got {V.shape}")
        checks.coordinates(V, f"{label} vertices")
        self.vertices = V.copy()
        self.vertices.setflags(write=False)
        self.two_sided = checks.flag(two_sided, "two_sided")
        self.loop_starts, self.loop_totals, self.corner_verts = self._topology(
            faces, loop_starts, loop_totals, corner_verts
        )
        self._pieces()
        self._bvh = None

    # ---------------------------------------------------------------- input
    def _label(self):
        return f"mesh {self.name!r}" if self.name else "mesh"

    def _topology(self, faces, loop_starts, loop_totals, corner_verts):
        """(loop_starts, loop_totals, corner_verts) as int64 arrays, checked."""
        label = self._label()
        blender = [x is not None for x in (loop_starts, loop_totals, corner_verts)]
        if faces is not None and any(blender):
            raise ValueError(f"{label}: give faces or loop_starts/loop_totals/corner_verts, not both")
        if faces is None:
            if not all(blender):
                raise ValueError(f"{label}: give faces, or all of loop_starts, loop_totals and corner_verts")
            starts, totals, corners = (
                self._indices(x, f"{label} {n}")
                for x, n in (
                    (loop_starts, "loop_starts"),
                    (loop_totals, "loop_totals"),
                    (corner_verts, "corner_verts"),
                )
            )
            if starts.shape != totals.shape:
                raise ValueError(f"{label}: loop_starts and loop_totals must have one entry per face")
            if totals.size and (np.any(starts < 0) or np.any(starts + totals > corners.size)):
                raise ValueError(f"{label}: loop_starts + loop_totals run past corner_verts ({corners.size})")
        else:
            if isinstance(faces, np.ndarray) and faces.ndim == 2:
                faces = list(faces)
            try:
                lists = [self._indices(f, f"{label} face {k}") for k, f in enumerate(faces)]
            except checks.ArgumentTypeError:
                raise
            except TypeError as error:
                raise checks.ArgumentTypeError(f"{label} faces must be a sequence of index lists") from error
            totals = np.array([f.size for f in lists], dtype=np.int64)
            starts = ragged.starts(totals)
            corners = np.concatenate(lists) if lists else np.zeros(0, np.int64)
        if totals.size == 0:
            raise ValueError(f"{label} has no faces")
        short = np.flatnonzero(totals < 3)
        if short.size:
            raise ValueError(f"{label}: faces {_listed(short)} have fewer than 3 corners")
        bad = np.flatnonzero((corners < 0) | (corners >= len(self.vertices)))
        if bad.size:
            raise ValueError(
                f"{label}: vertex indices must be in 0 .. {len(self.vertices) - 1},"
                f" got {_listed(corners[bad])} (corner entries {_listed(bad)})"
            )
        for array in (starts, totals, corners):
            array.setflags(write=False)
        return starts, totals, corners

    @staticmethod
    def _indices(value, name):
        array = np.asarray(value)
        if array.ndim != 1 or not (np.issubdtype(array.dtype, np.integer) or array.size == 0):
            raise checks.ArgumentTypeError(
                f"{name} must be a 1-D integer array, got {array.dtype} {array.shape}"
            )
        return array.astype(np.int64)

    # ---------------------------------------------------------------- pieces
    def _corner_face(self):
        """Face of each corner entry and the corner's position in its face, shapes (L',)."""
        face = np.repeat(np.arange(self.loop_totals.size), self.loop_totals)
        return face, ragged.local(self.loop_totals)

    def corners_of(self, f):
        """Vertex indices of face f, shape (n,)."""
        s, t = self.loop_starts[f], self.loop_totals[f]
        return self.corner_verts[s : s + t]

    def _pieces(self):
        """Newell normals, planarity and convexity per face; flat pieces; skipped faces."""
        F = self.loop_totals.size
        face, local = self._corner_face()
        entry = self.loop_starts[face] + local
        following = self.loop_starts[face] + (local + 1) % self.loop_totals[face]
        P = self.vertices[self.corner_verts[entry]]
        Q = self.vertices[self.corner_verts[following]]
        # Newell's vector area: half the sum of p_i x p_i+1 (about the face's first corner)
        origin = self.vertices[self.corner_verts[self.loop_starts]][face]
        newell = np.zeros((F, 3))
        np.add.at(newell, face, np.cross(P - origin, Q - origin))
        length = np.linalg.norm(newell, axis=1)
        lo = np.full((F, 3), np.inf)
        hi = np.full((F, 3), -np.inf)
        np.minimum.at(lo, face, P)
        np.maximum.at(hi, face, P)
        size = np.linalg.norm(hi - lo, axis=1)
        degenerate = length <= 2.0 * DEGENERATE_RTOL * size**2
        unit = np.divide(newell, length[:, None], out=np.zeros_like(newell), where=~degenerate[:, None])
        # planar: every corner within PLANAR_RTOL * size of the plane through the corners' mean
        centre = np.zeros((F, 3))
        np.add.at(centre, face, P)
        centre /= self.loop_totals[:, None]
        height = np.einsum("ki,ki->k", P - centre[face], unit[face])
        offplane = np.zeros(F)
        np.maximum.at(offplane, face, np.abs(height))
        planar = offplane <= PLANAR_RTOL * size
        # convex: every turn at a corner has the normal's sign (collinear corners pass)
        previous = self.loop_starts[face] + (local - 1) % self.loop_totals[face]
        R = self.vertices[self.corner_verts[previous]]
        turn = np.einsum("ki,ki->k", np.cross(P - R, Q - P), unit[face])
        reflex = np.zeros(F, dtype=bool)
        np.logical_or.at(reflex, face, turn < -1e-12 * size[face] ** 2)
        convex = ~reflex

        self.face_normal = unit
        skipped = np.flatnonzero(degenerate)
        pieces_v, pieces_f = [], []
        n = self.loop_totals
        # triangles: one piece (a, b, c, a)
        tri = np.flatnonzero((n == 3) & ~degenerate)
        if tri.size:
            c = self.corner_verts[self.loop_starts[tri, None] + np.arange(3)]
            pieces_v.append(np.column_stack([c, c[:, 0]]))
            pieces_f.append(tri)
        # planar convex quads: one piece; the rest split as Blender does, (0, 1, 2) and (0, 2, 3)
        quad = (n == 4) & ~degenerate
        whole = np.flatnonzero(quad & planar & convex)
        if whole.size:
            pieces_v.append(self.corner_verts[self.loop_starts[whole, None] + np.arange(4)])
            pieces_f.append(whole)
        split = np.flatnonzero(quad & ~(planar & convex))
        if split.size:
            c = self.corner_verts[self.loop_starts[split, None] + np.arange(4)]
            first = np.column_stack([c[:, 0], c[:, 1], c[:, 2], c[:, 0]])
            second = np.column_stack([c[:, 0], c[:, 2], c[:, 3], c[:, 0]])
            pieces_v.append(np.stack([first, second], 1).reshape(-1, 4))
            pieces_f.append(np.repeat(split, 2))
        # n-gons: a fan if planar and convex, else ear clipping
        for f in np.flatnonzero((n > 4) & ~degenerate):
            corners = self.corners_of(f)
            if planar[f] and convex[f]:
                k = np.arange(1, corners.size - 1)
                triangles = np.column_stack([np.zeros_like(k), k, k + 1])
            else:
                triangles = ear_clip(self.vertices[corners], unit[f])
            c = corners[triangles]
            pieces_v.append(np.column_stack([c, c[:, 0]]))
            pieces_f.append(np.full(len(c), f))
        if not pieces_v:
            raise ValueError(f"{self._label()}: every face has zero area")
        piece_v = np.concatenate(pieces_v)
        piece_f = np.concatenate(pieces_f)
        order = np.argsort(piece_f, kind="stable")
        piece_v, piece_f = piece_v[order], piece_f[order]
        corners = self.vertices[piece_v]
        # flat quads: corners projected onto the face plane (float32 noise), then triangles
        # whose own area vanishes (collinear fan or ear corners) are dropped
        whole_piece = piece_v[:, 3] != piece_v[:, 0]
        if whole_piece.any():
            fw = piece_f[whole_piece]
            h = np.einsum("kci,ki->kc", corners[whole_piece] - centre[fw][:, None], unit[fw])
            corners[whole_piece] -= h[..., None] * unit[fw][:, None]
        piece_area = 0.5 * np.linalg.norm(
            np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1]), axis=1
        )
        keep = piece_area > DEGENERATE_RTOL * size[piece_f] ** 2
        self.piece_vertices, self.piece_face, self.piece_corners = piece_v[keep], piece_f[keep], corners[keep]
        self.piece_area = piece_area[keep]
        self.face_area = np.bincount(self.piece_face, weights=self.piece_area, minlength=F)
        self.skipped = np.union1d(skipped, np.setdiff1d(np.arange(F), self.piece_face)).astype(np.int64)
        for array in (
            self.piece_vertices,
            self.piece_face,
            self.piece_corners,
            self.face_area,
            self.face_normal,
        ):
            array.setflags(write=False)
        if self.skipped.size:
            warnings.warn(
                f"{self._label()}: skipped {self.skipped.size} face(s) with no area: {_listed(self.skipped)}",
                stacklevel=3,
            )

    # ---------------------------------------------------------------- surface API
    @property
    def face_count(self):
        return int(self.loop_totals.size)

    def area(self):
        """Total area (m^2) of the faces (skipped ones have none)."""
        return float(self.face_area.sum())

    def pieces(self):
        """The flat pieces as `core.Quad`s (triangles with p01 = p00), in `piece_face` order."""
        if not hasattr(self, "_quads"):
            self._quads = [Quad(*c) for c in self.piece_corners]
        return self._quads

    def _with(self, vertices, reverse):
        """A mesh with new vertex positions, each face's corners reversed if `reverse`."""
        corners = self.corner_verts
        if reverse:
            face, local = self._corner_face()
            start, total = self.loop_starts[face], self.loop_totals[face]
            corners = self.corner_verts[start + (total - local) % total]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (the skipped faces were named for this mesh already)
            return PolygonMesh(
                vertices,
                loop_starts=self.loop_starts,
                loop_totals=self.loop_totals,
                corner_verts=corners,
                two_sided=self.two_sided,
                name=self.name,
            )

    def flipped(self):
        """The same mesh with the other side as front (every face's corners reversed)."""
        return self._with(self.vertices, True)

    def transformed(self, matrix):
        """The image under a 4x4 affine matrix (column vectors: x' = M @ [x, 1]).

        The image of the front side stays the front side: a mirroring matrix reverses the faces'
        corner order.
        """
        linear, offset = checks.affine(matrix)
        return self._with(self.vertices @ linear.T + offset, np.linalg.det(linear) < 0.0)

    def triangles(self):
        """The pieces as triangles (quads as (p00, p10, p11) and (p00, p11, p01)), shape (T, 3, 3),
        and the face of each, shape (T,)."""
        c = self.piece_corners
        quad = self.piece_vertices[:, 3] != self.piece_vertices[:, 0]
        first = c[:, [0, 1, 2]]
        second = c[quad][:, [0, 2, 3]]
        return np.concatenate([first, second]), np.concatenate([self.piece_face, self.piece_face[quad]])

    @property
    def piece_neighbours(self):
        """The piece across each edge of each piece, shape (P, 4) int (edge w joins corners w and
        w + 1): -1 where the edge has no area (a triangle's repeated corner), bounds the mesh, is
        shared by more than two pieces or by two whose corner orders disagree (a consistently
        oriented neighbour runs the edge the other way round). Computed once, then kept."""
        if getattr(self, "_neighbours", None) is None:
            self._neighbours = _neighbours(self.piece_vertices, len(self.vertices))
            self._neighbours.setflags(write=False)
        return self._neighbours

    @property
    def orientation(self):
        """+1 if the mesh is closed (every edge of a piece shared with one consistently oriented
        other: `piece_neighbours`) with its fronts facing out of the region it bounds, -1 if they
        face into it (a room), 0 if it is not closed. The sign is that of the enclosed volume
        (divergence theorem over the pieces' triangles (0, 1, 2) and (0, 2, 3))."""
        if not _closed(self.piece_vertices, self.piece_neighbours):
            return 0
        a, b, c, d = self.piece_corners.transpose(1, 0, 2)
        return int(np.sign(np.sum(a * (np.cross(b, c) + np.cross(c, d)))))

    def occlusion_bvh(self):
        """The BVH over `triangles()` used by occlusion queries (built once, then kept)."""
        if self._bvh is None:
            from .bvh import BVH

            triangles, _ = self.triangles()
            self._bvh = BVH.from_primitives(triangles=triangles, object_id=np.zeros(len(triangles), np.int64))
        return self._bvh

    @property
    def front_hull(self):
        """(normals (P, 3), offsets (P,)) of the face planes if the whole mesh lies in front of
        every one of them, else None.

        Then the mesh bounds the convex region {x : n . x >= d for every plane} from outside (a
        closed room with inward faces, or part of one): a segment between two points of that
        region never crosses the mesh (it touches it at most at its ends). At most
        MAX_HULL_PLANES distinct planes are tried.
        """
        planes = self._distinct_planes()
        if planes is None or planes[2].min(initial=0.0) < -planes[3]:
            return None
        return planes[0], planes[1]

    @property
    def convex_solid(self):
        """Whether the whole mesh lies behind (or on) every face plane: the surface of a convex
        solid with its fronts outward (a segment leaving a front never meets the mesh again).
        At most MAX_HULL_PLANES distinct planes are tried."""
        planes = self._distinct_planes()
        return planes is not None and planes[2].max(initial=0.0) <= planes[3]

    @property
    def solid_hull(self):
        """(normals (P, 3), offsets (P,), slack) of the face planes if the mesh is a closed
        convex solid with its fronts outward (`convex_solid`, closed once corners at one place
        are one vertex), else None.

        The solid is then {x : n . x <= d for every plane} to within slack (m), the farthest a
        corner lies from its side's plane (float32 coordinates scatter), and a segment meets the
        mesh where it enters or leaves that polytope: one clip against P planes (Cyrus & Beck
        1978) answers what a walk down its triangle hierarchy does, but for crossings within
        slack of the segment's ends."""
        if not hasattr(self, "_solid"):
            self._solid = None
            if self.convex_solid:
                # (meshes often repeat corners along sharp edges, in float32 not always to the
                # last bit; fronts out follows from convex_solid)
                size = np.linalg.norm(self.vertices.max(0) - self.vertices.min(0))
                pieces = _welded(self.vertices, HULL_RTOL * size)[self.piece_vertices]
                if _closed(pieces, _neighbours(pieces, len(self.vertices))):
                    normal, offset, _, _, slack = self._distinct_planes()
                    self._solid = (normal, offset, slack)
        return self._solid

    def solid_facets(self):
        """The closed convex solid (`solid_hull`) as a mesh of its facets, one polygon per face
        plane (the convex hull of the corners in it), or None. A cube subdivided twice is 96
        pieces and 6 facets: exact shadows take meshes of a few pieces (`occluded.MESH_PIECES`)."""
        hull = self.solid_hull
        if hull is None:
            return None
        if not hasattr(self, "_facets"):
            normal, offset, slack = hull
            size = np.linalg.norm(self.vertices.max(0) - self.vertices.min(0))
            V = np.unique(self.piece_corners.reshape(-1, 3), axis=0)
            faces = []
            for n, d in zip(normal, offset):
                on = np.flatnonzero(np.abs(V @ n - d) <= 2.0 * slack + 1e-12 * size)
                a, b = _plane_axes(n)  # (a, b, n) right-handed: counterclockwise about n
                # in-plane coordinates snapped to a grid finer than the planes' slack allows
                # (float32 corners scatter; near-duplicates would break the hull's order), as
                # integers below 2^24, so that the hull's turn tests are exact
                step = max(8.0 * slack, 1e-7 * size)
                grid = np.round(np.column_stack([V[on] @ a, V[on] @ b]) / step)
                _, first = np.unique(grid, axis=0, return_index=True)
                faces.append(on[first[_hull_2d(grid[first], 0.5)]])
            used, index = np.unique(np.concatenate(faces), return_inverse=True)
            starts = np.cumsum([0] + [len(f) for f in faces])
            self._facets = PolygonMesh(
                V[used],
                [index[s:e] for s, e in zip(starts[:-1], starts[1:])],
                name=f"{self.name} facets" if self.name else None,
            )
        return self._facets

    def _distinct_planes(self):
        """(normals (P, 3), offsets (P,), heights of every piece corner over them (C, P),
        tolerance, slack: the farthest a piece's corner lies from its plane) for at most
        MAX_HULL_PLANES distinct piece planes, else None (cached).

        A piece shares the plane of an earlier one when it faces the same way and its corners lie
        within HULL_RTOL of the mesh's size of that plane: Blender keeps coordinates in float32,
        so the faces of a subdivided cube scatter about 1e-7 of its size around their side's
        plane, and their normals by more (a rounding of unit normals to 1e-9 found 62 and more
        planes on a cube subdivided twice)."""
        if not hasattr(self, "_planes"):
            self._planes = None
            size = np.linalg.norm(self.vertices.max(0) - self.vertices.min(0))
            tolerance = HULL_RTOL * size
            C = self.piece_corners
            normal = np.cross(C[:, 2] - C[:, 0], C[:, 3] - C[:, 1])  # (front: corners run CCW)
            norm = np.linalg.norm(normal, axis=1)
            left = np.flatnonzero(norm > 0.0)  # (pieces without area have no plane)
            normal[left] /= norm[left, None]
            offset = np.einsum("pi,pi->p", normal, C.mean(1))
            first, slack = [], 0.0
            while left.size and len(first) <= MAX_HULL_PLANES:
                r = left[0]
                height = np.abs(C[left] @ normal[r] - offset[r]).max(1)
                same = (normal[left] @ normal[r] > 0.5) & (height <= tolerance)
                first.append(r)
                slack = max(slack, height[same].max())
                left = left[~same]
            if first and len(first) <= MAX_HULL_PLANES:
                n, d = normal[first], offset[first]
                self._planes = (n, d, C.reshape(-1, 3) @ n.T - d[None], tolerance, float(slack))
        return self._planes

    @property
    def planar(self):
        """(point, unit normal) if every face lies in one plane (to HULL_RTOL of the mesh's
        size: `_distinct_planes`), else None."""
        planes = self._distinct_planes()
        if planes is None or len(planes[0]) != 1:
            return None
        return self.piece_corners.reshape(-1, 3).mean(0), planes[0][0]

    def merge_coplanar(self):
        """The same surface with every region of coplanar faces as one face, and the map from
        faces to the new ones.

        A region is a set of faces joined across edges that two faces share with opposite
        corner orders (one front), all corners within COPLANAR_RTOL of the mesh's size of one
        plane (Blender's float32 coordinates scatter about 1e-7). It becomes one polygon, its
        boundary loop with straight-through corners dropped, if that loop is the region's whole
        boundary (no holes, no corner visited twice) and encloses the region's area (the faces
        do not overlap); a loop that is not convex takes at most MERGED_CORNERS corners. Other
        regions keep their faces. The union is the same surface, so light transport needs only
        the patches its size asks for: a floor subdivided into 48 x 48 faces becomes one quad.

        Returns
        -------
        mesh : PolygonMesh
            The merged mesh (the same vertices; those inside a region belong to no face), with
            the regions' faces first in order of their least face, then the other faces.
        face_map : ndarray of int, shape (F,)
            The new face of each face (-1 for skipped faces).
        """
        F = self.face_count
        face, local = self._corner_face()
        a = self.corner_verts[self.loop_starts[face] + local]
        b = self.corner_verts[self.loop_starts[face] + (local + 1) % self.loop_totals[face]]
        size = float(np.linalg.norm(self.vertices.max(0) - self.vertices.min(0)))
        tolerance = COPLANAR_RTOL * size
        P = self.vertices[a]
        centre = np.zeros((F, 3))
        np.add.at(centre, face, P)
        centre /= self.loop_totals[:, None]
        height = np.zeros(F)
        np.maximum.at(height, face, np.abs(np.einsum("ki,ki->k", P - centre[face], self.face_normal[face])))
        flat = (height <= tolerance) & (self.face_area > 0.0)
        # faces joined across an edge: both flat, facing the same way, each in the other's plane
        one, two = _shared_edges(a, b, len(self.vertices))
        f1, f2 = face[one], face[two]
        n1, n2 = self.face_normal[f1], self.face_normal[f2]
        joined = (
            flat[f1]
            & flat[f2]
            & (np.einsum("ki,ki->k", n1, n2) > 0.5)
            & (np.abs(np.einsum("ki,ki->k", centre[f2] - centre[f1], n1)) <= tolerance)
            & (np.abs(np.einsum("ki,ki->k", centre[f1] - centre[f2], n2)) <= tolerance)
        )
        region, normal, point, area, off = _regions(self, joined, (f1, f2), P, centre)
        failed = np.flatnonzero((np.bincount(region, minlength=F) > 1) & (off > tolerance))
        if failed.size:
            # a gently curved surface chains faces that are each in their neighbours' planes:
            # split such regions by the planes of their faces (`_split_by_planes`) and join again
            plane = _split_by_planes(self, region, failed, P, centre, tolerance)
            joined &= plane[f1] == plane[f2]
            region, normal, point, area, off = _regions(self, joined, (f1, f2), P, centre)
        r = region[face]
        count = np.bincount(region, minlength=F)
        candidate = (count > 1) & (off <= tolerance) & (area > 0.0)
        # boundary edges (a -> b) of the candidate regions, grouped by region
        inner = np.zeros(a.size, bool)
        inner[one[joined]] = inner[two[joined]] = True
        edge = np.flatnonzero(~inner & candidate[r])
        edge = edge[np.argsort(r[edge], kind="stable")]
        loops = {}
        if edge.size:
            bounds = np.flatnonzero(np.diff(r[edge])) + 1
            for group in np.split(edge, bounds):
                k = int(r[group[0]])
                loop = _region_loop(self.vertices, a[group], b[group], normal[k], area[k], tolerance)
                if loop is not None:
                    loops[k] = loop
        regions = np.array(sorted(loops), np.int64)
        merged = np.isin(region, regions)
        kept = np.flatnonzero(~merged & (self.face_area > 0.0))
        face_map = np.full(F, -1, np.int64)
        face_map[merged] = np.searchsorted(regions, region[merged])
        face_map[kept] = regions.size + np.arange(kept.size)
        polygons = [loops[k] for k in regions.tolist()]
        totals = np.concatenate([[len(p) for p in polygons], self.loop_totals[kept]]).astype(np.int64)
        start = self.loop_starts[kept]
        corners = [self.corner_verts[ragged.expand(start, self.loop_totals[kept])[1]]]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (skipped faces were named for this mesh already)
            mesh = PolygonMesh(
                self.vertices,
                loop_starts=ragged.starts(totals),
                loop_totals=totals,
                corner_verts=np.concatenate(polygons + corners),
                two_sided=self.two_sided,
                name=self.name,
            )
        return mesh, face_map

    def __repr__(self):
        name = f"{self.name!r}, " if self.name else ""
        return f"PolygonMesh({name}{len(self.vertices)} vertices, {self.face_count} faces)"


def _regions(mesh, joined, edges, P, centre):
    """Regions of faces joined across the shared edges (f1, f2) where `joined`, and each
    region's plane: (region of each face (its least face) (F,), unit normals (F, 3) and points
    (F, 3) of the planes (area-weighted), areas (F,), farthest corner from the plane (F,)),
    indexed by region. P (L, 3) are the corners in face order, centre (F, 3) the faces'."""
    F = mesh.face_count
    f1, f2 = edges
    region = _components(F, f1[joined], f2[joined])
    normal = np.zeros((F, 3))
    np.add.at(normal, region, mesh.face_normal * mesh.face_area[:, None])
    area = np.bincount(region, mesh.face_area, minlength=F)
    point = np.zeros((F, 3))
    np.add.at(point, region, centre * mesh.face_area[:, None])
    live = area > 0.0
    normal[live] /= np.linalg.norm(normal[live], axis=1)[:, None]
    point[live] /= area[live, None]
    r = np.repeat(region, mesh.loop_totals)
    off = np.zeros(F)
    np.maximum.at(off, r, np.abs(np.einsum("ki,ki->k", P - point[r], normal[r])))
    return region, normal, point, area, off


def _split_by_planes(mesh, region, failed, P, centre, tolerance):
    """A plane label per face, shape (F,): in each `failed` region, the faces in order take the
    plane of the first face not yet placed if all their corners lie within `tolerance` of it
    and they face its way (at most MAX_SPLIT_PLANES planes a region, and none after ALONE_PLANES
    in a row that took only their own face: a curved surface; the faces left then get a label
    each); other faces keep their region."""
    F = mesh.face_count
    plane = region.copy()
    totals = mesh.loop_totals
    first_corner = ragged.starts(totals)
    label = F
    by_region = np.argsort(region, kind="stable")
    first = np.searchsorted(region[by_region], failed)
    last = np.searchsorted(region[by_region], failed, side="right")
    for lo, hi in zip(first.tolist(), last.tolist()):
        faces = by_region[lo:hi]
        _, rows = ragged.expand(first_corner[faces], totals[faces])
        starts = ragged.starts(totals[faces])
        corners, normals = P[rows], mesh.face_normal[faces]
        left = np.ones(faces.size, bool)
        alone = 0  # planes in a row that took only their own face
        for _ in range(MAX_SPLIT_PLANES):
            if not left.any() or alone == ALONE_PLANES:
                break
            seed = faces[np.argmax(left)]
            height = np.maximum.reduceat(np.abs((corners - centre[seed]) @ mesh.face_normal[seed]), starts)
            same = left & (height <= tolerance) & (normals @ mesh.face_normal[seed] > 0.5)
            plane[faces[same]] = label
            left &= ~same
            label += 1
            alone = alone + 1 if np.count_nonzero(same) == 1 else 0
        plane[faces[left]] = label + np.arange(np.count_nonzero(left))
        label += np.count_nonzero(left)
    return plane


def _plane_axes(normal):
    """Unit axes (e1, e2) of the plane normal to the unit vector `normal`, with (e1, e2, normal)
    right-handed (counterclockwise about `normal`), each shape (3,)."""
    e1 = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal))])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


def _shared_edges(a, b, vertex_count):
    """Corner edges (a -> b, shape (L,) each) shared by exactly two corners that run them the
    opposite way round (consistently oriented neighbours): their indices (one, two), shape (E,)."""
    key = np.minimum(a, b) * vertex_count + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    _, first, count = np.unique(key[order], return_index=True, return_counts=True)
    pair = first[count == 2]
    one, two = order[pair], order[pair + 1]
    opposite = (a[one] == b[two]) & (a[one] != b[one])
    return one[opposite], two[opposite]


def _components(n, i, j):
    """Connected components of n nodes joined by edges (i, j): each node's least node index,
    shape (n,) (labels spread along edges, then jump to their labels' labels, until none
    changes: about log of the diameter rounds on a grid)."""
    label = np.arange(n)
    while True:
        before = label
        least = np.minimum(label[i], label[j])
        label = label.copy()
        np.minimum.at(label, i, least)
        np.minimum.at(label, j, least)
        label = label[label]
        if np.array_equal(label, before):
            return label


def _region_loop(vertices, a, b, normal, area, tolerance):
    """The boundary of a planar region as one polygon, or None.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
    a, b : ndarray of int, shape (E,)
        The region's boundary edges a -> b (its faces' corner order).
    normal : ndarray, shape (3,)
        Unit normal of the region's plane.
    area : float
        Sum of its faces' areas.
    tolerance : float
        Distance (m) within which corners count as on one line, and the area test's width.

    Returns
    -------
    ndarray of int or None
        Vertex indices of the loop with straight-through corners dropped, in the faces' order;
        None if the edges are not one simple loop (holes, a corner visited twice), the loop
        does not enclose `area` (overlapping faces), or it is not convex and has more than
        MERGED_CORNERS corners.
    """
    order = np.argsort(a, kind="stable")
    a, b = a[order], b[order]
    if np.any(a[1:] == a[:-1]):
        return None
    following = np.searchsorted(a, b)  # the edge that starts where each one ends
    if np.any(following >= a.size) or np.any(a[np.minimum(following, a.size - 1)] != b):
        return None
    loop, at = [], 0
    for _ in range(a.size):
        loop.append(a[at])
        at = following[at]
        if at == 0:
            break
    if at != 0 or len(loop) != a.size:
        return None
    loop = np.array(loop, np.int64)
    e1, e2 = _plane_axes(normal)
    xy = (vertices[loop] - vertices[loop[0]]) @ np.column_stack([e1, e2])

    def enclosed(points):
        x, y = points[:, 0], points[:, 1]
        perimeter = np.linalg.norm(np.roll(points, -1, 0) - points, axis=1).sum()
        signed = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
        return abs(signed - area) <= 2.0 * tolerance * perimeter + 1e-12 * area

    if not enclosed(xy):
        return None
    before, after = np.roll(xy, 1, 0), np.roll(xy, -1, 0)
    chord = after - before
    turn = chord[:, 0] * (xy[:, 1] - before[:, 1]) - chord[:, 1] * (xy[:, 0] - before[:, 0])
    corner = np.abs(turn) > tolerance * np.linalg.norm(chord, axis=1)
    if corner.sum() >= 3 and enclosed(xy[corner]):
        loop, xy = loop[corner], xy[corner]
    edge = np.roll(xy, -1, 0) - xy
    then = np.roll(edge, -1, 0)
    convex = np.all(edge[:, 0] * then[:, 1] - edge[:, 1] * then[:, 0] > 0.0)
    if not convex and loop.size > MERGED_CORNERS:
        return None
    return loop


def _hull_2d(points, tolerance):
    """Indices of the convex hull of distinct points (K, 2), counterclockwise, corners only
    (turns of at most `tolerance` in cross product dropped): Andrew's monotone chain (Andrew, "Another
    efficient algorithm for convex hulls in two dimensions", Inf. Process. Lett. 9, 1979)."""
    order = np.lexsort((points[:, 1], points[:, 0]))

    def chain(indices):
        out = []
        for i in indices:
            while len(out) >= 2:
                o, a = points[out[-2]], points[out[-1]]
                if (a[0] - o[0]) * (points[i][1] - o[1]) - (a[1] - o[1]) * (points[i][0] - o[0]) > tolerance:
                    break
                out.pop()
            out.append(i)
        return out

    lower, upper = chain(order), chain(order[::-1])
    return np.array(lower[:-1] + upper[:-1], dtype=np.int64)


def _welded(vertices, tolerance):
    """Each vertex's representative (the least index among the vertices chained to it by steps
    under `tolerance` per coordinate), shape (V,) int. Two points closer than that per coordinate
    share a cell of side 2 tolerance in at least one of the 8 grids shifted by half a cell along
    any of the axes; labels spread through shared cells until none changes."""
    label = np.arange(len(vertices))
    scaled = vertices / (2.0 * max(tolerance, 1e-300))
    cells = [
        np.unique(np.floor(scaled + 0.5 * np.array(shift)), axis=0, return_inverse=True)[1]
        for shift in np.ndindex(2, 2, 2)
    ]
    while True:
        before = label.copy()
        for cell in cells:
            cell = cell.ravel()
            least = np.full(cell.max(initial=-1) + 1, len(vertices))
            np.minimum.at(least, cell, label)
            label = np.minimum(label, least[cell])
        if np.array_equal(label, before):
            return label


def _closed(pieces, neighbours):
    """Whether every edge with an area of pieces (P, 4) has a neighbour (`_neighbours`)."""
    edge = pieces != np.roll(pieces, -1, axis=1)
    return bool(np.all(neighbours[edge] >= 0))


def _neighbours(pieces, vertex_count):
    """The piece across each edge of pieces (P, 4) of vertex indices, shape (P, 4) int (edge w
    joins corners w and w + 1): -1 where the edge has no area, bounds the mesh, is shared by
    more than two pieces or by two whose corner orders disagree."""
    P = len(pieces)
    a = pieces.ravel()
    b = np.roll(pieces, -1, axis=1).ravel()
    edge = np.arange(4 * P)
    live = a != b
    key = np.minimum(a, b) * vertex_count + np.maximum(a, b)
    edge, key = edge[live], key[live]
    order = np.argsort(key, kind="stable")
    edge, key = edge[order], key[order]
    _, first, count = np.unique(key, return_index=True, return_counts=True)
    pair = first[count == 2]
    one, two = edge[pair], edge[pair + 1]
    opposite = a[one] == b[two]  # (a[one] = b[two] and b[one] = a[two])
    one, two = one[opposite], two[opposite]
    neighbours = np.full(4 * P, -1, dtype=np.int64)
    neighbours[one], neighbours[two] = two // 4, one // 4
    return neighbours.reshape(P, 4)


def _listed(indices, most=20):
    """'1, 2, 3' (the first `most`, then '... (n in all)')."""
    text = ", ".join(str(int(i)) for i in indices[:most])
    return text + (f", ... ({len(indices)} in all)" if len(indices) > most else "")


def ear_clip(points, normal):
    """Triangles of a simple polygon by ear clipping (Eberly 2002), shape (n - 2, 3) local indices.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Corners in order (counter-clockwise about `normal`).
    normal : ndarray, shape (3,)
        Unit normal of the polygon's (best-fit) plane; corners are projected onto it.
    """
    e1, e2 = _plane_axes(normal)  # a 2-D frame in the plane
    xy = np.column_stack([(points - points[0]) @ e1, (points - points[0]) @ e2])
    scale = max(np.abs(xy).max(), 1e-300)
    xy = xy / scale
    remaining = list(range(len(points)))
    triangles = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    guard = 0
    while len(remaining) > 3 and guard < 4 * len(points) ** 2:
        guard += 1
        m = len(remaining)
        for i in range(m):
            a, b, c = remaining[i - 1], remaining[i], remaining[(i + 1) % m]
            if cross(xy[a], xy[b], xy[c]) <= 1e-14:
                continue  # reflex or collinear corner: not an ear
            others = [k for k in remaining if k not in (a, b, c)]
            if others:
                p = xy[others]
                d1 = (xy[b][0] - xy[a][0]) * (p[:, 1] - xy[a][1]) - (xy[b][1] - xy[a][1]) * (
                    p[:, 0] - xy[a][0]
                )
                d2 = (xy[c][0] - xy[b][0]) * (p[:, 1] - xy[b][1]) - (xy[c][1] - xy[b][1]) * (
                    p[:, 0] - xy[b][0]
                )
                d3 = (xy[a][0] - xy[c][0]) * (p[:, 1] - xy[c][1]) - (xy[a][1] - xy[c][1]) * (
                    p[:, 0] - xy[c][0]
                )
                if np.any((d1 >= 0) & (d2 >= 0) & (d3 >= 0)):
                    continue  # another corner inside: not an ear
            triangles.append((a, b, c))
            remaining.pop(i)
            break
        else:
            # no ear found (self-intersecting or numerically collinear polygon): fan the rest
            break
    for k in range(1, len(remaining) - 1):
        triangles.append((remaining[0], remaining[k], remaining[k + 1]))
    return np.array(triangles, dtype=np.int64).reshape(-1, 3)
