"""The paper's models on one flat vector, for scipy's ``solve_ivp`` (a helper, not a family).

State of a single congruent group of N agents in R^d, everything in absolute coordinates:

    first order  (A-2)   y = (xbar (N, d), O (N, d, d))
    second order (A-1)   y = (xbar (N, d), xbar' (N, d), O (N, d, d), W (N, d, d))

with W_i = O_i' O_i^T the spatial angular velocity.  The right-hand sides are the
paper's equations written directly with numpy, in mean-field form (S = sum_k O_k):

    (A-2)  xbar_i' = kappa/(gamma N) sum_k (xbar_k - xbar_i)
           O_i'    = W_i O_i,   W_i = kappa/(2 gamma N) (S O_i^T - O_i S^T)
    (A-1)  xbar_i'' = (-gamma xbar_i' + kappa/N sum_k (xbar_k - xbar_i)) / m
           O_i'     = W_i O_i
           W_i'     = (-gamma W_i + kappa/(2N) (S O_i^T - O_i S^T)) / m

(for (A-1), m (O'' O^T + O' O'^T) = m W', so the second line of (A-1) is the last line
here).  Nothing keeps O_i in SO(d): a general-purpose solver preserves O^T O = I only
to its tolerance (Lemma 2.1 is a property of the ODE, not of the method).
"""

import numpy as np


class FlatSystem:
    """Packing, unpacking and the right-hand side of one congruent group for solve_ivp."""

    def __init__(self, order, n, d, kappa, gamma, mass=0.0):
        if order not in (1, 2):
            raise ValueError(f"order must be 1 or 2, got {order}")
        self.order, self.n, self.d = order, int(n), int(d)
        self.kappa, self.gamma, self.mass = float(kappa), float(gamma), float(mass)
        nx, nm = self.n * self.d, self.n * self.d * self.d
        sizes = [nx, nm] if order == 1 else [nx, nx, nm, nm]
        self.names = ("x", "rot") if order == 1 else ("x", "v", "rot", "w")
        self.shapes = dict(zip(self.names, [(n, d), (n, d, d)] if order == 1 else
                               [(n, d), (n, d), (n, d, d), (n, d, d)]))
        ends = np.cumsum(sizes)
        self.slices = {k: slice(int(e - s), int(e)) for k, s, e in zip(self.names, sizes, ends)}
        self.size = int(ends[-1])

    @classmethod
    def for_scene(cls, scene):
        m = scene.model
        if len(m.groups) != 1 or m.groups[0].scales is not None or m.inter_group:
            raise ValueError(f"{scene.name}: the flat system is written for one congruent group")
        return cls(m.order, m.n_agents, m.dim, m.kappa, m.gamma, m.mass)

    # -- packing ----------------------------------------------------------------------------
    def pack(self, x, rot, v=None, w=None):
        parts = {"x": x, "rot": rot, "v": v, "w": w}
        return np.concatenate([np.asarray(parts[k], dtype=float).ravel() for k in self.names])

    def initial(self, scene):
        """y0 of a scene: absolute centroids, rotation matrices, velocities and skew W."""
        m = scene.model
        gs = scene.initial.groups[0]
        grp = m.rotations
        rot = grp.to_matrices(gs.rot)
        if self.order == 1:
            return self.pack(gs.x + scene.origin, rot)
        return self.pack(gs.x + scene.origin, rot, gs.v, grp.algebra_to_skew(gs.w))

    def unpack(self, y):
        """dict of arrays; y is one state (size,) or solve_ivp's columns (size, T): leading T."""
        y = np.asarray(y)
        if y.ndim == 1:
            return {k: y[self.slices[k]].reshape(self.shapes[k]) for k in self.names}
        yt = y.T
        return {k: yt[:, self.slices[k]].reshape((-1,) + self.shapes[k]) for k in self.names}

    # -- the right-hand side ----------------------------------------------------------------
    def torque(self, o):
        """S O_i^T - O_i S^T for every i (the sum over k through the mean field S)."""
        d = self.d
        s = o.sum(axis=0)
        b = (o.reshape(-1, d) @ s.T).reshape(-1, d, d)        # O_i S^T
        return np.swapaxes(b, 1, 2) - b

    def rhs(self, t, y):
        n, d = self.n, self.d
        sl = self.slices
        x = y[sl["x"]].reshape(n, d)
        o = y[sl["rot"]].reshape(n, d, d)
        out = np.empty_like(y)
        pull = x.mean(axis=0) - x                             # 1/N sum_k (xbar_k - xbar_i)
        if self.order == 1:
            out[sl["x"]] = ((self.kappa / self.gamma) * pull).ravel()
            w = (self.kappa / (2.0 * self.gamma * n)) * self.torque(o)
            out[sl["rot"]] = (w @ o).ravel()
            return out
        v = y[sl["v"]].reshape(n, d)
        w = y[sl["w"]].reshape(n, d, d)
        out[sl["x"]] = v.ravel()
        out[sl["v"]] = ((self.kappa * pull - self.gamma * v) / self.mass).ravel()
        out[sl["rot"]] = (w @ o).ravel()
        torque = (self.kappa / (2.0 * n)) * self.torque(o)
        out[sl["w"]] = ((torque - self.gamma * w) / self.mass).ravel()
        return out

    # -- diagnostics ------------------------------------------------------------------------
    def energy(self, rot, w=None):
        """Proposition 2.2 (i): (m/N) sum |W_i|^2 + (kappa/N) sum |O_i - Obar|^2 (leading T axis).

        Computed from the matrices as they are (not projected onto SO(d))."""
        rot = np.asarray(rot)
        dev = rot - rot.mean(axis=-3, keepdims=True)
        e = (self.kappa / self.n) * np.sum(dev * dev, axis=(-3, -2, -1))
        if self.order == 2 and w is not None:
            e = e + (self.mass / self.n) * np.sum(np.asarray(w) ** 2, axis=(-3, -2, -1))
        return e

