"""The link store of hierarchical radiosity: which node gathers light from which, and how well.

A link (r <- s) carries light from source node s to receiver node r: r's radiosity gains
rho_r F(r -> s) V(r, s) B_s, with F the unoccluded area-average form factor (exact kernels of
`transport.pair_form_factors`) and V the pair's visibility (`visibility.pair_visibility`).
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
        FULL (no occluder in the shaft), PARTIAL (something in the shaft, V > 0) or HIDDEN
        (V = 0), from `bounds`.
    v_error : ndarray, shape (K,)
        Absolute error V may have: 0 with nothing in the shaft, `refine.SAMPLED_VISIBILITY_ERROR`
        for rays, the allowance it was computed to for an exact V.
    f_error : ndarray, shape (K,)
        Relative error F may have: 0 for a pair whose rule converged or no kink can defeat,
        `transport.KINK_RULE_ERROR` for a kinked pair's fixed rule, the allowance it was refined
        to otherwise (`refine.Refinement`).
    variation : ndarray, shape (K,)
        The quadratic's largest residual at the receiver's sample points (of the visible point
        factor for shadowed links), plus any correction of its mean: the link's factor
        uncertainty over the receiver (see `refine`).
    source_variation : ndarray, shape (K,)
        Relative variation of F(y -> receiver) over the source's sample points y (0 for sources
        without children), which bounds the error of carrying the source's mean radiosity.
    peak : ndarray, shape (K,)
        max of F(x -> source) over the receiver's sample points.
    shape : ndarray, shape (K, 6)
        F(x -> source) V(x, source) / V over the receiver as a quadratic in its normalised
        parameters (`hierarchy`), whose mean over the receiver is F (so V times it is the
        visible point factor, of mean F V).
    """

    FIELDS = (
        "receiver",
        "source",
        "F",
        "V",
        "visibility",
        "v_error",
        "f_error",
        "variation",
        "source_variation",
        "peak",
        "shape",
    )
    TYPES = (np.int64, np.int64, np.float64, np.float64, np.int8) + (np.float64,) * 6

    def __init__(self):
        for name, kind in zip(self.FIELDS, self.TYPES):
            setattr(self, name, np.zeros((0, 6) if name == "shape" else 0, dtype=kind))

    def __len__(self):
        return self.receiver.size

    def append(self, **columns):
        """Add links given as equal-length arrays named by `FIELDS`."""
        sizes = {len(columns[name]) for name in self.FIELDS}
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

    def gather(self, B, size, mask=None):
        """sum over links into each receiver of the quadratic F(x) V B_source, shape (size, 6, C).

        Parameters
        ----------
        B : ndarray, shape (M, C)
            Node radiosities.
        size : int
            Number of nodes (rows of the result).
        mask : ndarray of bool, shape (K,), optional
            Only these links.
        """
        out = np.zeros((size, 6, B.shape[1]))
        V = self.V if mask is None else np.where(mask, self.V, 0.0)
        for c in range(B.shape[1]):
            weight = V * B[self.source, c]
            for k in range(6):
                out[:, k, c] = np.bincount(self.receiver, weight * self.shape[:, k], minlength=size)
        return out

    def row_sums(self, size, mask=None):
        """sum over links into each receiver (only `mask`, bool (K,), if given) of the quadratic
        F(x) V, shape (size, 6, 1)."""
        out = np.zeros((size, 6, 1))
        V = self.V if mask is None else np.where(mask, self.V, 0.0)
        for k in range(6):
            out[:, k, 0] = np.bincount(self.receiver, V * self.shape[:, k], minlength=size)
        return out

    def nbytes(self):
        return sum(getattr(self, name).nbytes for name in self.FIELDS)
