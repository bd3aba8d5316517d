"""Many patches stacked so that one call evaluates points on all of them."""

import numpy as np


class SurfaceSet:
    """Patches stacked for vectorised evaluation by index.

    Patches that share a geometry (cut by `subpatch`/`split`) share its parameters; geometries
    of one class are evaluated together by that class's `stacked_derivatives`.

    Parameters
    ----------
    surfaces : sequence of Surface, length S
    """

    def __init__(self, surfaces):
        self.surfaces = list(surfaces)
        geometry_slot = {}
        self.classes = []  # (geometry class, [geometries])
        class_slot = {}
        group = np.empty(len(self.surfaces), dtype=np.int64)
        local = np.empty(len(self.surfaces), dtype=np.int64)
        for k, surface in enumerate(self.surfaces):
            geometry = surface.geometry
            key = id(geometry)
            if key not in geometry_slot:
                cls = type(geometry)
                if cls not in class_slot:
                    class_slot[cls] = len(self.classes)
                    self.classes.append((cls, []))
                members = self.classes[class_slot[cls]][1]
                geometry_slot[key] = (class_slot[cls], len(members))
                members.append(geometry)
            group[k], local[k] = geometry_slot[key]
        self.group = group
        self.local = local
        self.stacks = [cls.stack(members) for cls, members in self.classes]
        self.orientation = np.array([s.orientation for s in self.surfaces], dtype=np.float64)
        self.boxes = np.array([np.ravel(s.domain) for s in self.surfaces], dtype=np.float64).reshape(-1, 4)

    def __len__(self):
        return len(self.surfaces)

    def derivatives(self, index, u, v):
        """Points and parameter derivatives.

        Parameters
        ----------
        index : ndarray of int, shape (K,)
            Patch of each point.
        u, v : ndarray, shape (K,)

        Returns
        -------
        P, Pu, Pv : ndarray, shape (K, 3)
        """
        index = np.asarray(index, dtype=np.int64)
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        group = self.group[index]
        if len(self.classes) == 1 or (index.size and np.all(group == group[0])):
            g = 0 if len(self.classes) == 1 else int(group[0])
            return self.classes[g][0].stacked_derivatives(self.stacks[g], self.local[index], u, v)
        P, Pu, Pv = (np.empty((index.size, 3)) for _ in range(3))
        for g, (cls, _) in enumerate(self.classes):
            sel = np.flatnonzero(group == g)
            if sel.size:
                P[sel], Pu[sel], Pv[sel] = cls.stacked_derivatives(
                    self.stacks[g], self.local[index[sel]], u[sel], v[sel]
                )
        return P, Pu, Pv

    def evaluate(self, index, u, v):
        """Points and unnormalised front normals, each shape (K, 3); see `Surface.evaluate`."""
        P, Pu, Pv = self.derivatives(index, u, v)
        # Pu x Pv, component by component (np.cross is slower on (K, 3))
        N = np.empty_like(Pu)
        N[:, 0] = Pu[:, 1] * Pv[:, 2] - Pu[:, 2] * Pv[:, 1]
        N[:, 1] = Pu[:, 2] * Pv[:, 0] - Pu[:, 0] * Pv[:, 2]
        N[:, 2] = Pu[:, 0] * Pv[:, 1] - Pu[:, 1] * Pv[:, 0]
        N *= self.orientation[index][:, None]
        return P, N

    def cell_boxes(self, index, lu, lv, i, j):
        """Parameter boxes of dyadic cells.

        Cell (lu, lv, i, j) of patch `index` is the (i, j)-th of the 2^lu x 2^lv equal
        sub-boxes of the patch's domain.

        Returns
        -------
        ndarray, shape (K, 4)
            (u0, u1, v0, v1) of each cell.
        """
        box = self.boxes[index]
        du = (box[:, 1] - box[:, 0]) * np.ldexp(1.0, -np.asarray(lu))
        dv = (box[:, 3] - box[:, 2]) * np.ldexp(1.0, -np.asarray(lv))
        u0 = box[:, 0] + i * du
        v0 = box[:, 2] + j * dv
        return np.stack([u0, u0 + du, v0, v0 + dv], -1)
