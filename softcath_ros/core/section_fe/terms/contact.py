"""Frictionless self-contact of a hole's wall (the lumen): a smoothly clamped log-barrier.

The wall is the closed polygon through its corner and midside nodes (counter-clockwise about
the hole). Every wall vertex i is kept away from every wall segment j not incident to it by

    Pi_c = kappa sum_(i,j) l_i w(t_ij) b(s_ij),   b(s) = -(s - s_hat)^2 ln(s / s_hat) for s < s_hat, else 0,

s_ij the squared distance from vertex i to the line of segment j, t_ij the parameter of its
foot on the segment (0 at its start, 1 at its end), s_hat = d_hat^2 with d_hat the barrier
distance, and l_i the reference wall length vertex i stands for (the sum is a quadrature over
the wall). The window w(t) is 1 on the segment, 0 more than WINDOW beyond its ends, and a C2
step across each end such that the windows of two collinear neighbours sum to 1: the wall is
treated as one smooth surface, not a chain of segments with corners. So the potential is C2
everywhere (b = b' = b'' = 0 at s_hat; w C2), which keeps Newton quadratic when pairs enter or
leave the barrier's range or a foot slides from one segment to the next (a point-segment
distance, as in IPC, switches between point-line and point-point and its Hessian jumps there:
Newton then cycles at the folded shoulders of a closing lumen). b -> inf as s -> 0, so the
walls never touch; a state whose wall polygon crosses itself (a Newton step that jumped a
vertex through the opposite wall) is inadmissible (energy inf), so the solver backtracks
instead of tunnelling.

Why a barrier (not a penalty or an augmented Lagrangian): the gap stays positive at every
iterate, not only at convergence; it needs no outer loop (augmented Lagrangian), and the answer
depends on d_hat only through the equilibrium gap, a fraction of d_hat (kappa = KAPPA_SCALE /
d_hat^3 puts that gap at a fixed fraction of d_hat for a given contact pressure in units of c1).
"""
from __future__ import annotations

import numpy as np

from . import INADMISSIBLE, Contribution, SparseContribution

# kappa = KAPPA_SCALE / d_hat^3 (non-dimensional: lengths / R, energy / (c1 R^2)): at a contact
# pressure p_c (/ c1) the gap is about 2 KAPPA_SCALE d_hat / p_c.
KAPPA_SCALE = 0.25
# half-width of the window's steps at the segment's ends (fraction of the segment)
WINDOW = 0.25

# the pair's local coordinates z = (p, a, b): p the vertex, (a, b) the segment
_J_E = np.array([[0, 0, -1, 0, 1, 0], [0, 0, 0, -1, 0, 1]], float)   # e = b - a = J_e z
_J_V = np.array([[1, 0, -1, 0, 0, 0], [0, 1, 0, -1, 0, 0]], float)   # v = p - a = J_v z
_ROT = np.array([[0.0, 1.0], [-1.0, 0.0]])                           # e x v = e^T ROT v
_D2C = _J_E.T @ _ROT @ _J_V + (_J_E.T @ _ROT @ _J_V).T              # d2(e x v)/dz2
_D2L = 2 * _J_E.T @ _J_E                                             # d2(e.e)/dz2
_D2Q = _J_V.T @ _J_E + _J_E.T @ _J_V                                 # d2(v.e)/dz2


def barrier(s, s_hat):
    """b(s), b'(s), b''(s) of the clamped log-barrier (valid for 0 < s < s_hat)."""
    r = s - s_hat
    ln = np.log(s / s_hat)
    b = -r * r * ln
    b1 = -2 * r * ln - r * r / s
    b2 = -2 * ln - 4 * r / s + r * r / (s * s)
    return b, b1, b2


def barrier_value(s, s_hat):
    """b(s) alone (``barrier``'s first value, the same arithmetic)."""
    r = s - s_hat
    return -r * r * np.log(s / s_hat)


def _step(u):
    return u**3 * (10 - 15 * u + 6 * u * u)


def smooth_step(u):
    """S(u) = 6u^5 - 15u^4 + 10u^3 on [0, 1] (0 below, 1 above), S', S'': C2."""
    u = np.clip(u, 0.0, 1.0)
    return _step(u), 30 * u * u * (1 - u) ** 2, 60 * u * (1 - u) * (1 - 2 * u)


def window_value(t):
    """w(t) alone (``window``'s first value, the same arithmetic)."""
    h = 2 * WINDOW
    return _step(np.clip((t + WINDOW) / h, 0.0, 1.0)) * _step(np.clip((1 + WINDOW - t) / h, 0.0, 1.0))


def window(t):
    """w(t), w'(t), w''(t): 1 on [WINDOW, 1 - WINDOW], 0 outside [-WINDOW, 1 + WINDOW]."""
    h = 2 * WINDOW
    lo, lo1, lo2 = smooth_step((t + WINDOW) / h)
    hi, hi1, hi2 = smooth_step((1 + WINDOW - t) / h)
    return lo * hi, (lo1 * hi - lo * hi1) / h, (lo2 * hi - 2 * lo1 * hi1 + lo * hi2) / h**2


def line_distance2(p, a, b, derivatives: bool = True):
    """Squared distance s from points p to the lines through segments (a, b) and the foot's
    parameter t (each (n,)); with ``derivatives`` also ds, dt (n, 6) and d2s, d2t (n, 6, 6)
    with respect to (p, a, b)."""
    e, v = b - a, p - a
    L = np.einsum("ni,ni->n", e, e)
    c = e[:, 0] * v[:, 1] - e[:, 1] * v[:, 0]
    q = np.einsum("ni,ni->n", v, e)
    s, t = c * c / L, q / L
    if not derivatives:
        return s, t
    dc = np.zeros((len(p), 6))
    dc[:, 0], dc[:, 1] = -e[:, 1], e[:, 0]                 # dc/dp
    dc[:, 4], dc[:, 5] = v[:, 1], -v[:, 0]                 # dc/db
    dc[:, 2:4] = -(dc[:, 0:2] + dc[:, 4:6])                # dc/da (translation invariance)
    dL = np.concatenate([np.zeros((len(p), 2)), -2 * e, 2 * e], 1)
    dq = e @ _J_V + v @ _J_E
    inv = 1.0 / L
    o = lambda x, y: x[:, :, None] * y[:, None, :]         # noqa: E731 (outer product per pair)
    n3 = lambda x: x[:, None, None]                        # noqa: E731
    ds = (2 * c * inv)[:, None] * dc - (c * c * inv**2)[:, None] * dL
    d2s = (n3(2 * inv) * o(dc, dc) + n3(2 * c * inv) * _D2C - n3(2 * c * inv**2) * (o(dc, dL) + o(dL, dc))
           + n3(2 * c * c * inv**3) * o(dL, dL) - n3(c * c * inv**2) * _D2L)
    dt = inv[:, None] * dq - (q * inv**2)[:, None] * dL
    d2t = (n3(inv) * _D2Q - n3(inv**2) * (o(dq, dL) + o(dL, dq)) - n3(q * inv**2) * _D2L
           + n3(2 * q * inv**3) * o(dL, dL))
    return s, t, ds, dt, d2s, d2t


def point_segment_distance(p, a, b):
    """Distance from points p to segments (a, b) (the nearest point of the segment)."""
    e, v = b - a, p - a
    t = np.clip(np.einsum("ni,ni->n", v, e) / np.einsum("ni,ni->n", e, e), 0.0, 1.0)
    return np.linalg.norm(v - t[:, None] * e, axis=1)


def _squared_distances(A, B):
    """|a_i - b_j|^2 (len(A), len(B))."""
    dx = A[:, 0, None] - B[None, :, 0]
    dy = A[:, 1, None] - B[None, :, 1]
    return dx * dx + dy * dy


def _largest_move(d) -> float:
    """The largest component of the moves ``d`` (m, 2) of a wall's points but for their common
    translation (the middle of their range): a translation changes no distance between them."""
    return float(np.max(np.abs(d - 0.5 * (d.max(axis=0) + d.min(axis=0)))))


def segments_cross(P, i, j):
    """True where polygon segments i and j (vertex k to k + 1) properly intersect."""
    m = len(P)
    a, b = P[i], P[(i + 1) % m]
    c, d = P[j], P[(j + 1) % m]

    def cross(u, w):
        return u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]

    return (cross(b - a, c - a) * cross(b - a, d - a) < 0) & (cross(d - c, a - c) * cross(d - c, b - c) < 0)


class WallContact:
    """Self-contact of the wall of one hole (edges (b, 3), counter-clockwise about the hole)."""

    def __init__(self, X, edges: np.ndarray, distance: float, n_u: int):
        """``distance``: the barrier distance d_hat (/ R)."""
        self.ids = edges[:, :2].ravel()                     # polygon vertices: corner, midside, ...
        m = len(self.ids)
        self.m, self.n_u, self._X = m, n_u, X
        self.d_hat = float(distance)
        self.s_hat = self.d_hat ** 2
        self.kappa = KAPPA_SCALE / self.d_hat ** 3
        self._last_active = None                              # (wall points, what _active found there)
        P = X[self.ids]
        seg = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
        self.weight = 0.5 * (seg + np.roll(seg, 1))          # reference wall length per vertex
        vi, sj = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        off = (sj - vi) % m                                  # segment j runs from vertex j to j + 1
        keep = (off >= 1) & (off <= m - 2)                   # every segment not incident to vertex i
        self.pv, self.ps = vi[keep], sj[keep]
        self._pair_of = np.full((m, m), -1, dtype=np.int64)  # (vertex, segment) -> index into pv, ps
        self._pair_of[self.pv, self.ps] = np.arange(len(self.pv))
        self._valid = self._pair_of >= 0
        self._clear = None                                   # (wall points, margin) where no pair was near
        # segment pairs for the crossing test: neither the same nor neighbours
        si, sk = np.triu_indices(m, k=2)
        far = (sk - si) <= m - 2
        self.cross_i, self.cross_j = si[far], sk[far]
        self._may_cross = np.zeros((m, m), dtype=bool)
        self._may_cross[self.cross_i, self.cross_j] = True
        d = np.empty(2 * m, dtype=np.int64)
        d[0::2], d[1::2] = 2 * self.ids, 2 * self.ids + 1
        self.dofs = d[None]                                  # one block: every wall coordinate

    def _points(self, x):
        u = x[:self.n_u].reshape(-1, 2)
        return self._X[self.ids] + u[self.ids]

    def _pair_points(self, P, sel=slice(None)):
        return P[self.pv[sel]], P[self.ps[sel]], P[(self.ps[sel] + 1) % self.m]

    def min_gap(self, x) -> float:
        """The smallest distance (/ R) from a wall vertex to a wall segment not incident to it;
        negative if the wall polygon crosses itself."""
        P = self._points(x)
        if np.any(segments_cross(P, self.cross_i, self.cross_j)):
            return -1.0
        return float(point_segment_distance(*self._pair_points(P)).min())

    def _candidates(self, P):
        """A broad phase (exact: a superset of what it stands for, in the full lists' order):
        (segment pairs that may cross, vertex-segment pairs that may be within the barrier's range),
        from the distances of the vertices to the segments' midpoints (a wall has a few hundred
        vertices at most: all of them, faster than a tree; where none is a candidate, how far each was
        is kept, ``_active``'s shortcut). Segments i and k cross only if vertex i lies within 1.5 x
        the longest segment's length of segment k's midpoint and vertex k of segment i's; a vertex within d_hat
        of a segment's line, its foot inside the window, lies within d_hat + (1/2 + WINDOW) x that
        length of the segment's midpoint."""
        Q = np.roll(P, -1, axis=0)
        longest2 = float(np.max(np.einsum("ij,ij->i", Q - P, Q - P)))
        d2 = _squared_distances(P, 0.5 * (P + Q))
        close = d2 <= 2.25 * longest2 * (1 + 1e-9) ** 2
        crossing = np.nonzero(self._may_cross & close & close.T)
        reach = (self.d_hat + (0.5 + WINDOW) * np.sqrt(longest2)) * (1 + 1e-9)
        pair = self._pair_of[d2 <= reach * reach]     # row-major: in the list's order
        pair = pair[pair >= 0]
        self._clear = None
        if not len(pair) and not len(crossing[0]):
            # how far every distance is from making a candidate: while no wall point moves by a ninth
            # of it but for a common translation (distances change by at most 2, the thresholds by 3 x
            # the largest move), none can
            d = np.sqrt(d2)
            margin = min(float(np.min(np.maximum(d, d.T)[self._may_cross])) - 1.5 * np.sqrt(longest2) * (1 + 1e-9),
                         float(np.min(d[self._valid])) - reach)
            self._clear = (P, margin) if margin > 0 else None
        return crossing, pair

    def _active(self, x):
        """(wall points, the pairs within the barrier's range, their squared distances and feet) or
        None if inadmissible; the last answer is kept for the same wall points (a trial's energy,
        then its assembly)."""
        P = self._points(x)
        last = self._last_active
        if last is not None and np.array_equal(P, last[0]):
            return last[1]
        clear = self._clear
        if clear is not None and _largest_move(P - clear[0]) < clear[1] / 9:
            got = P, np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)   # no pair can be near yet
            self._last_active = (P, got)
            return got
        crossing, candidates = self._candidates(P)
        got = None
        if not np.any(segments_cross(P, *crossing)):
            s, t = line_distance2(*self._pair_points(P, candidates), derivatives=False)
            near = (s < self.s_hat) & (t > -WINDOW) & (t < 1 + WINDOW)
            if not np.any(s[near] <= 0):
                got = P, candidates[near], s[near], t[near]
        self._last_active = (P, got)
        return got

    def energy(self, x, pressures) -> float:
        got = self._active(x)
        if got is None:
            return np.inf
        P, a, s, t = got
        if not len(a):
            return 0.0                  # (what the sum over no pair gives)
        return float(self.kappa * np.sum(self.weight[self.pv[a]] * window_value(t) * barrier_value(s, self.s_hat)))

    def assemble(self, x, pressures) -> Contribution:
        got = self._active(x)
        if got is None:
            return INADMISSIBLE
        P, a = got[:2]
        m = self.m
        g = np.zeros((1, 2 * m))
        if not len(a):
            return SparseContribution(0.0, g, np.zeros(0, dtype=np.int64), np.zeros(0), 2 * m)
        s, t, ds, dt, d2s, d2t = line_distance2(*self._pair_points(P, a))
        b, b1, b2 = barrier(s, self.s_hat)
        w, w1, w2 = window(t)
        k = self.kappa * self.weight[self.pv[a]]
        n3 = lambda v: (k * v)[:, None, None]                 # noqa: E731
        gl = (k * w * b1)[:, None] * ds + (k * w1 * b)[:, None] * dt
        Hl = (n3(w * b2) * ds[:, :, None] * ds[:, None, :] + n3(w * b1) * d2s
              + n3(w1 * b1) * (ds[:, :, None] * dt[:, None, :] + dt[:, :, None] * ds[:, None, :])
              + n3(w2 * b) * dt[:, :, None] * dt[:, None, :] + n3(w1 * b) * d2t)
        verts = np.stack([self.pv[a], self.ps[a], (self.ps[a] + 1) % m], 1)
        loc = np.empty((len(a), 6), dtype=np.int64)
        loc[:, 0::2], loc[:, 1::2] = 2 * verts, 2 * verts + 1
        np.add.at(g[0], loc, gl)
        # the Hessian's non-zero entries, each summed over the pairs in their order (as np.add.at would)
        keys, inverse = np.unique((loc[:, :, None] * (2 * m) + loc[:, None, :]).ravel(), return_inverse=True)
        values = np.bincount(inverse.ravel(), weights=Hl.ravel(), minlength=len(keys))
        return SparseContribution(float(np.sum(k * w * b)), g, keys, values, 2 * m)


def _point_in_polygon(c, P) -> bool:
    """True if the point c lies inside the closed polygon P (m, 2) (even-odd rule)."""
    a, b = P, np.roll(P, -1, axis=0)
    crosses = (a[:, 1] > c[1]) != (b[:, 1] > c[1])
    x_at = a[:, 0] + (c[1] - a[:, 1]) * (b[:, 0] - a[:, 0]) / np.where(b[:, 1] == a[:, 1], 1.0, b[:, 1] - a[:, 1])
    return bool(np.count_nonzero(crosses & (x_at > c[0])) % 2)


class DeviceContact:
    """Frictionless contact of a hole's wall with a rigid round device lying free in the hole.

    The device's centre c is an unknown of its own (an extra node of the problem, not in any
    element). The wall is sampled at SAMPLES points per segment (q = (1 - t) a + t b,
    t = 0, 1/SAMPLES, ...), and each is kept off the device by

        kappa sum_q (L_j / SAMPLES) b((|q - c| - r)^2) + 1/2 k_c |c - c_wall|^2,

    L_j the segment's reference length, r the device radius, b the barrier of the wall's
    self-contact. Every term is smooth in (c, a, b), so Newton stays quadratic; a chord can dip
    between two samples by at most L^2 / (8 r SAMPLES^2) (0.2 um for D/20 and a 1.2 mm device).
    The weak spring k_c (CENTRING, units c1) to the wall's mean position holds the free device
    where nothing touches it (its force is below 0.1 % of the pressure's on the wall). The
    device's centre leaving the wall polygon is inadmissible."""

    CENTRING = 1e-2
    SAMPLES = 4

    def __init__(self, X, edges: np.ndarray, radius: float, distance: float, device_node: int, n_u: int):
        self.ids = edges[:, :2].ravel()
        m = len(self.ids)
        self.m, self.n_u, self._X = m, n_u, X
        self.r = float(radius)
        self.d_hat = float(distance)
        self.s_hat = self.d_hat ** 2
        self.kappa = KAPPA_SCALE / self.d_hat ** 3
        P = X[self.ids]
        length = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
        self.mean_weights = 0.5 * (length + np.roll(length, 1))
        self.mean_weights /= self.mean_weights.sum()
        k = self.SAMPLES
        self.seg = np.repeat(np.arange(m), k)                   # sample -> segment
        self.t = np.tile(np.arange(k) / k, m)                   # sample -> position on it
        self.w = np.repeat(length / k, k)                       # sample -> wall length it stands for
        self.node = device_node
        d = np.empty(2 * m + 2, dtype=np.int64)
        d[0:2 * m:2], d[1:2 * m:2] = 2 * self.ids, 2 * self.ids + 1
        d[2 * m:] = 2 * device_node, 2 * device_node + 1
        self.dofs = d[None]

    def _points(self, x):
        u = x[:self.n_u].reshape(-1, 2)
        return self._X[self.ids] + u[self.ids], self._X[self.node] + u[self.node]

    def _samples(self, P, c):
        a, b = P[self.seg], P[(self.seg + 1) % self.m]
        q = (1 - self.t)[:, None] * a + self.t[:, None] * b
        return q - c

    def gaps(self, x) -> np.ndarray:
        """Distance (/ R) from the device's surface to each wall sample point (negative: overlap)."""
        P, c = self._points(x)
        return np.linalg.norm(self._samples(P, c), axis=1) - self.r

    def _state(self, x):
        P, c = self._points(x)
        if not _point_in_polygon(c, P):
            return None
        v = self._samples(P, c)
        g = np.linalg.norm(v, axis=1) - self.r
        if np.any(g <= 0):
            return None
        return P, c, v, g, np.flatnonzero(g < self.d_hat)

    def _spring(self, P, c):
        off = c - self.mean_weights @ P
        return 0.5 * self.CENTRING * float(off @ off), off

    def energy(self, x, pressures) -> float:
        got = self._state(x)
        if got is None:
            return np.inf
        P, c, v, g, a = got
        b = barrier(g[a] ** 2, self.s_hat)[0]
        return float(self.kappa * np.sum(self.w[a] * b)) + self._spring(P, c)[0]

    def assemble(self, x, pressures) -> Contribution:
        got = self._state(x)
        if got is None:
            return INADMISSIBLE
        P, c, v, g, a = got
        m = self.m
        nloc = 2 * m + 2
        grad = np.zeros((1, nloc))
        H = np.zeros((1, nloc, nloc))
        E, off = self._spring(P, c)
        coef = np.concatenate([np.repeat(-self.mean_weights, 2), [1.0, 1.0]])   # d(off_comp)/d(local)
        for comp in (0, 1):
            sel = np.arange(comp, nloc, 2)
            grad[0, sel] += self.CENTRING * off[comp] * coef[sel]
            H[0][np.ix_(sel, sel)] += self.CENTRING * np.outer(coef[sel], coef[sel])
        if len(a):
            va, ga, t = v[a], g[a], self.t[a]
            rho = ga + self.r                                      # |q - c|
            bb, b1, b2 = barrier(ga**2, self.s_hat)
            # B(rho^2) = b((rho - r)^2): derivatives in s = rho^2
            q1 = 1 - self.r / rho
            q2 = self.r / (2 * rho**3)
            B1, B2 = b1 * q1, b2 * q1 * q1 + b1 * q2
            k = self.kappa * self.w[a]
            # s = |v|^2, v = (1 - t) a + t b - c: ds = 2 J^T v, d2s = 2 J^T J, J = [-I, (1-t) I, t I]
            coef3 = np.stack([-np.ones_like(t), 1 - t, t], 1)      # (n, 3): c, segment start, end
            ds = 2 * (coef3[:, :, None] * va[:, None, :]).reshape(len(a), 6)
            J = np.zeros((len(a), 2, 6))
            for j in range(3):
                J[:, 0, 2 * j] = J[:, 1, 2 * j + 1] = coef3[:, j]
            d2s = 2 * np.einsum("nki,nkj->nij", J, J)
            gl = (k * B1)[:, None] * ds
            Hl = (k * B2)[:, None, None] * ds[:, :, None] * ds[:, None, :] + (k * B1)[:, None, None] * d2s
            loc = np.empty((len(a), 6), dtype=np.int64)
            loc[:, 0:2] = [2 * m, 2 * m + 1]
            s0, s1 = self.seg[a], (self.seg[a] + 1) % m
            loc[:, 2], loc[:, 3], loc[:, 4], loc[:, 5] = 2 * s0, 2 * s0 + 1, 2 * s1, 2 * s1 + 1
            np.add.at(grad[0], loc, gl)
            np.add.at(H[0], (loc[:, :, None], loc[:, None, :]), Hl)
            E += float(np.sum(k * bb))
        return Contribution(E, grad, H)
