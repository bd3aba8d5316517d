"""The same NURBS surface under another parametrisation: knot insertion, degree elevation, a
shifted and scaled domain. Test tools, independent of core/nurbs.py's evaluation.

- knot insertion: Boehm's algorithm (W. Boehm, "Inserting new knots into B-spline curves",
  Computer-Aided Design 12 (1980) 199-201; Piegl & Tiller, "The NURBS Book", A5.1);
- degree elevation: each knot raised to full multiplicity p (Bezier extraction, P&T 5.6), each
  Bezier segment elevated by the classical formula Q_i = i/(p+1) P_(i-1) + (1 - i/(p+1)) P_i
  (P&T eq. 5.36), the segments joined with interior knots of multiplicity p + 1: the same
  surface, only C0 across the old knots in its parametrisation;
- both in homogeneous coordinates (w P, w), so rational nets stay exact.
"""

import numpy as np

import core


def _insert_curve(Pw, U, p, t):
    """Insert knot t once into a curve of degree p with homogeneous points Pw (n, d). Boehm."""
    U = np.asarray(U, float)
    k = np.searchsorted(U, t, side="right") - 1
    s = int(np.sum(U == t))
    n = Pw.shape[0]
    Q = np.empty((n + 1,) + Pw.shape[1:])
    Q[: k - p + 1] = Pw[: k - p + 1]
    Q[k - s + 1 :] = Pw[k - s :]
    for i in range(k - p + 1, k - s + 1):
        a = (t - U[i]) / (U[i + p] - U[i])
        Q[i] = a * Pw[i] + (1 - a) * Pw[i - 1]
    return Q, np.insert(U, k + 1, t)


def _elevate_curve(Pw, U, p):
    """Degree p -> p + 1 for a clamped curve: decompose into Bezier segments, elevate each."""
    U = np.asarray(U, float)
    inner = np.unique(U[p + 1 : -p - 1])
    for t in inner:
        while np.sum(U == t) < p:
            Pw, U = _insert_curve(Pw, U, p, t)
    segments = (Pw.shape[0] - 1) // p
    out = [Pw[:1]]
    for j in range(segments):
        B = Pw[j * p : j * p + p + 1]
        E = np.empty((p + 2,) + B.shape[1:])
        E[0], E[-1] = B[0], B[-1]
        for i in range(1, p + 1):
            a = i / (p + 1)
            E[i] = a * B[i - 1] + (1 - a) * B[i]
        out.append(E[1:])
    breaks = np.unique(U)
    knots = np.concatenate(
        [[breaks[0]] * (p + 2)] + [[b] * (p + 1) for b in breaks[1:-1]] + [[breaks[-1]] * (p + 2)]
    )
    return np.concatenate(out), knots


class Net:
    """A NURBS control net: points (nu, nv, 3), weights (nu, nv), orders, knot vectors."""

    def __init__(self, points, weights, order_u, order_v, knots_u, knots_v):
        self.points, self.weights = np.asarray(points, float), np.asarray(weights, float)
        self.order_u, self.order_v = order_u, order_v
        self.knots_u, self.knots_v = np.asarray(knots_u, float), np.asarray(knots_v, float)

    def surface(self):
        return core.NurbsSurface(
            self.points, self.weights, self.order_u, self.order_v, self.knots_u, self.knots_v
        )

    def homogeneous(self):
        return np.concatenate([self.points * self.weights[..., None], self.weights[..., None]], -1)

    @staticmethod
    def from_homogeneous(H, ou, ov, ku, kv):
        w = H[..., 3]
        return Net(H[..., :3] / w[..., None], w, ou, ov, ku, kv)

    def insert_knots(self, u=(), v=()):
        H, ku, kv = self.homogeneous(), self.knots_u, self.knots_v
        for t in u:
            H, ku = _insert_curve(H, ku, self.order_u - 1, t)
        for t in v:
            Ht, kv = _insert_curve(np.swapaxes(H, 0, 1), kv, self.order_v - 1, t)
            H = np.swapaxes(Ht, 0, 1)
        return Net.from_homogeneous(H, self.order_u, self.order_v, ku, kv)

    def elevate(self, du=1, dv=1):
        H, ku, kv, ou, ov = self.homogeneous(), self.knots_u, self.knots_v, self.order_u, self.order_v
        for _ in range(du):
            H, ku = _elevate_curve(H, ku, ou - 1)
            ou += 1
        for _ in range(dv):
            Ht, kv = _elevate_curve(np.swapaxes(H, 0, 1), kv, ov - 1)
            H = np.swapaxes(Ht, 0, 1)
            ov += 1
        return Net.from_homogeneous(H, ou, ov, ku, kv)

    def shift_domain(self, au=(3.0, 2.5), av=(-7.0, 0.25)):
        return Net(
            self.points,
            self.weights,
            self.order_u,
            self.order_v,
            au[0] + au[1] * self.knots_u,
            av[0] + av[1] * self.knots_v,
        )
