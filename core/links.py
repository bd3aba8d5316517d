"""The link store of hierarchical radiosity: which node gathers light from which, and how well.

A link (r <- s) carries light from source node s to receiver node r: r's radiosity gains
rho_r F(r -> s) V(r, s) B_s, with F the unoccluded area-average form factor (exact kernels of
`transport.pair_form_factors`) and V the pair's visibility (`transport.pair_visibility`).
Each link keeps what the refinement oracle needs to re-judge it without any kernel evaluation
(after a relight, say): the variation of the point-to-node factor over the receiver and the
link's visibility class (`bounds.FULL`, `PARTIAL` or `HIDDEN`).
"""

import numpy as np

from .bounds import PARTIAL


class Links:
    """Links in flat arrays (one row per link).

    Attributes
    ----------
    receiver, source : ndarray of int, shape (K,)
        Nodes of a `hierarchy.Hierarchy`.
    F : ndarray, shape (K,)
        Unoccluded form factor F(receiver -> source) (area average over the receiver).
    V : ndarray, shape (K,)
        Visibility fraction in [0, 1].
    visibility : ndarray of int8, shape (K,)
        FULL (no occluder in the shaft), PARTIAL (0 < V < 1) or HIDDEN (V = 0), from `bounds`.
    variation : ndarray, shape (K,)
        max - min of F(x -> source) over sample points x of the receiver (the link's factor
        uncertainty as a constant; see `refine`).
    peak : ndarray, shape (K,)
        max of F(x -> source) over the same points (the factor a partial link may be off by).
    """

    FIELDS = ("receiver", "source", "F", "V", "visibility", "variation", "peak")
    TYPES = (np.int64, np.int64, np.float64, np.float64, np.int8, np.float64, np.float64)

    def __init__(self):
        for name, kind in zip(self.FIELDS, self.TYPES):
            setattr(self, name, np.zeros(0, dtype=kind))

    def __len__(self):
        return self.receiver.size

    def append(self, **columns):
        """Add links given as equal-length arrays named by `FIELDS`."""
        sizes = {np.size(columns[name]) for name in self.FIELDS}
        if len(sizes) != 1:
            raise ValueError(f"link columns must have one length, got sizes {sorted(sizes)}")
        for name, kind in zip(self.FIELDS, self.TYPES):
            setattr(self, name, np.concatenate([getattr(self, name), np.asarray(columns[name], dtype=kind)]))

    def remove(self, rows):
        """Drop the links at `rows` (indices or a boolean mask)."""
        keep = np.ones(len(self), dtype=bool)
        keep[rows] = False
        for name in self.FIELDS:
            setattr(self, name, getattr(self, name)[keep])

    @property
    def transfer(self):
        """F V per link, shape (K,)."""
        return self.F * self.V

    @property
    def partial(self):
        """Links whose visibility is partial, shape (K,) bool."""
        return self.visibility == PARTIAL

    def gather(self, B, size):
        """sum over links into each receiver of F V B_source, shape (size, C).

        Parameters
        ----------
        B : ndarray, shape (M, C)
            Node radiosities.
        size : int
            Number of nodes (rows of the result).
        """
        t = self.transfer
        out = np.zeros((size, B.shape[1]))
        for c in range(B.shape[1]):
            out[:, c] = np.bincount(self.receiver, t * B[self.source, c], minlength=size)
        return out

    def row_sums(self, size):
        """sum over links into each receiver of F V, shape (size,)."""
        return np.bincount(self.receiver, self.transfer, minlength=size)

    def nbytes(self):
        return sum(getattr(self, name).nbytes for name in self.FIELDS)
