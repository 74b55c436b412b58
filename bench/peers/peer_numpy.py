"""Plain NumPy cloth, fully vectorised (no Python loop over springs or nodes).

Two force kernels:

* ``springlist``: the general mass-spring formulation, the same one the
  Rust code and the Taichi/Newton runs use: gather both ends of every spring,
  compute the force, scatter-add with a single ``np.bincount``.
* ``grid``: exploits the regular grid: each spring family is a pair of
  shifted array slices, so gather and scatter become slice arithmetic.
  This is the fastest plain-NumPy formulation, but only works for grids.
"""

from __future__ import annotations

import numpy as np

import cloth_spec as spec


class NumpyCloth:
    framework = "numpy"

    def __init__(self, cloth: spec.Cloth, precision: str, integrator: str, kernel: str = "springlist"):
        if precision not in ("f64", "f32"):
            raise ValueError(precision)
        self.dtype = np.float64 if precision == "f64" else np.float32
        self.precision = precision
        self.integrator = integrator
        self.kernel = kernel
        self.variant = kernel
        dt_ = self.dtype
        self.cloth = cloth
        n = spec.N_NODES
        self.n = n
        self.mass = cloth.mass.astype(dt_)[:, None]
        self.free = cloth.free.astype(dt_)[:, None]
        self.g = np.array(spec.GRAVITY, dtype=dt_)
        self.dt = dt_(spec.DT)
        self.drag = dt_(spec.DRAG)

        # spring list
        self.sa = cloth.a.astype(np.intp)
        self.sb = cloth.b.astype(np.intp)
        self.rest = cloth.rest.astype(dt_)
        self.k = cloth.k.astype(dt_)
        self.c = cloth.c.astype(dt_)
        comp = np.arange(3)
        # flat scatter index: +F_a into 3a+c, -F_a into 3b+c
        self.scatter_idx = np.concatenate(
            [(3 * self.sa[:, None] + comp).ravel(), (3 * self.sb[:, None] + comp).ravel()]
        )

        # grid families: slices of a (64, 64, 3) [j, i] view
        self.families = []
        for _name, (ai, aj), (bi, bj), k, c in spec.FAMILIES:
            si, sj = max(ai, bi), max(aj, bj)
            ni, nj = spec.N_SIDE - si, spec.N_SIDE - sj
            sl_a = (slice(aj, aj + nj), slice(ai, ai + ni))
            sl_b = (slice(bj, bj + nj), slice(bi, bi + ni))
            rest = float(np.hypot(bi - ai, bj - aj) * spec.H)
            self.families.append((sl_a, sl_b, dt_(k), dt_(c), dt_(rest)))
        self.forces = self._forces_springlist if kernel == "springlist" else self._forces_grid

        self.step = self._step_euler if integrator == "euler" else self._step_rk4
        self.reset()

    # -- forces -------------------------------------------------------------
    def _accel(self, f, v):
        """a = (F_springs + F_drag)/m + g, zero on pinned nodes."""
        f -= self.drag * self.mass * v
        return (f / self.mass + self.g) * self.free

    def _forces_springlist(self, x, v):
        d = x[self.sb] - x[self.sa]
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        u = d / length[:, None]
        dv = v[self.sb] - v[self.sa]
        s = self.k * (length - self.rest) + self.c * np.einsum("ij,ij->i", dv, u)
        fa = (s[:, None] * u).ravel()
        f = np.bincount(self.scatter_idx, np.concatenate([fa, -fa]), minlength=3 * self.n)
        return self._accel(f.reshape(self.n, 3).astype(self.dtype, copy=False), v)

    def _forces_grid(self, x, v):
        xg = x.reshape(spec.N_SIDE, spec.N_SIDE, 3)
        vg = v.reshape(spec.N_SIDE, spec.N_SIDE, 3)
        f = np.zeros_like(x)
        fg = f.reshape(spec.N_SIDE, spec.N_SIDE, 3)
        for sl_a, sl_b, k, c, rest in self.families:  # 6 families, not springs
            d = xg[sl_b] - xg[sl_a]
            length = np.sqrt(np.einsum("...i,...i->...", d, d))
            u = d / length[..., None]
            dv = vg[sl_b] - vg[sl_a]
            s = k * (length - rest) + c * np.einsum("...i,...i->...", dv, u)
            fa = s[..., None] * u
            fg[sl_a] += fa
            fg[sl_b] -= fa
        return self._accel(f, v)

    # -- integrators --------------------------------------------------------
    def reset(self):
        self.x = self.cloth.x0.astype(self.dtype)
        self.v = np.zeros_like(self.x)

    def _step_euler(self, n):
        dt = self.dt
        for _ in range(n):
            self.v += dt * self.forces(self.x, self.v)
            self.x += dt * self.v

    def _step_rk4(self, n):
        dt = self.dt
        for _ in range(n):
            x, v = self.x, self.v
            k1x, k1v = v, self.forces(x, v)
            x2, v2 = x + 0.5 * dt * k1x, v + 0.5 * dt * k1v
            k2x, k2v = v2, self.forces(x2, v2)
            x3, v3 = x + 0.5 * dt * k2x, v + 0.5 * dt * k2v
            k3x, k3v = v3, self.forces(x3, v3)
            x4, v4 = x + dt * k3x, v + dt * k3v
            k4x, k4v = v4, self.forces(x4, v4)
            self.x = x + (dt / 6) * (k1x + 2 * k2x + 2 * k3x + k4x)
            self.v = v + (dt / 6) * (k1v + 2 * k2v + 2 * k3v + k4v)

    def sync(self):
        pass

    def state(self):
        return self.x.astype(np.float64), self.v.astype(np.float64)
