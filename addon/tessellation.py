"""The parameters at which Blender tessellates a NURBS surface spline (numpy only).

Blender's `BKE_nurb_makeFaces` (source/blender/blenkernel/intern/curve.cc, reached from
`evaluate_surface_object` in displist.cc) samples each spline on a grid of
totu = point_count_u * resolution_u by totv = point_count_v * resolution_v parameters,
t_k = start + k * step over the spline's domain [start, end], with step = (end - start) / (tot - 1)
or / tot in a cyclic direction (the seam is not repeated), summing t += step in float32. The
mesh vertex of grid point (k_u, k_v) is k_u * totv + k_v, and the splines of one object follow
each other in order. tests/test_nurbs_blender.py checks this rule against bpy.
"""

import numpy as np


def sample_parameters(domain, count, resolution, cyclic):
    """Blender's float32-accumulated samples along one direction.

    Parameters
    ----------
    domain : (float, float)
        The spline's parameter range in this direction (`NurbsSurface.domain[0]` or `[1]`).
    count, resolution : int
        Point count and resolution of the spline in this direction.
    cyclic : bool

    Returns
    -------
    ndarray, shape (count * resolution,)
        float64 values clipped to `domain` (the float32 sum can overshoot the end by an ulp).
    """
    start, end = np.float32(domain[0]), np.float32(domain[1])
    total = int(count) * int(resolution)
    step = np.float32(end - start) / np.float32(total if cyclic else total - 1)
    # running float32 sum, the way Blender adds the step
    increments = np.full(total, step, dtype=np.float32)
    increments[0] = start
    samples = np.cumsum(increments, dtype=np.float32).astype(np.float64)
    return np.clip(samples, domain[0], domain[1])


def grid_parameters(domain, counts, resolutions, cyclic):
    """(u, v) of every tessellation vertex of one spline, in Blender's vertex order.

    Parameters
    ----------
    domain : ((u0, u1), (v0, v1))
    counts, resolutions : (int, int)
        Point counts and resolutions along u and v.
    cyclic : (bool, bool)

    Returns
    -------
    u, v : ndarray, shape (totu * totv,)
        Vertex k_u * totv + k_v has parameters (u[k_u], v[k_v]).
    """
    u = sample_parameters(domain[0], counts[0], resolutions[0], cyclic[0])
    v = sample_parameters(domain[1], counts[1], resolutions[1], cyclic[1])
    return np.repeat(u, v.size), np.tile(v, u.size)
