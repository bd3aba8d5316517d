"""The differential form-factor kernel of the parametric differential method.

With e = x2 - x1 and L = |e|, the kernel between two surface points is

    K = max(0, n1 . e) * max(0, -n2 . e) / (pi L^4)

where n1, n2 are unnormalised front normals (their lengths are area densities), so that
F(1 -> 2) = (1 / A1) * integral of K du1 dv1 du2 dv2 (Baranoski's formula; see seed SUMMARY.md).
A pair counts only where both front sides face each other. Cosines smaller than 1e-12 of
|n| L are treated as zero, so coplanar surfaces give exactly zero.
"""

import numpy as np

GRAZING = 1e-12  # cosines below this count as zero (coplanar and tangent pairs)


def kernel(x1, n1, x2, n2):
    """Clipped point-pair kernel K.

    Parameters
    ----------
    x1, x2 : ndarray, shape (..., 3)
        Points (m).
    n1, n2 : ndarray, shape (..., 3)
        Front normals at the points, any length (a unit n1 gives the kernel of dA1 -> surface 2).

    Returns
    -------
    ndarray, shape (...,)
        K in units of |n1| |n2| / m^2.
    """
    e = x2 - x1
    L2 = np.einsum("...i,...i->...", e, e)
    L = np.sqrt(L2)
    c1 = np.einsum("...i,...i->...", n1, e)
    c2 = -np.einsum("...i,...i->...", n2, e)
    len1 = np.sqrt(np.einsum("...i,...i->...", n1, n1))
    len2 = np.sqrt(np.einsum("...i,...i->...", n2, n2))
    facing = (c1 > GRAZING * len1 * L) & (c2 > GRAZING * len2 * L) & (L2 > 0.0)
    denominator = np.where(facing, np.pi * L2 * L2, 1.0)
    return np.where(facing, c1 * c2 / denominator, 0.0)
