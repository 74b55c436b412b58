"""Taichi cloth on the CPU backend, one thread.

Per-spring kernel with scatter-adds (the general mass-spring formulation,
like the Rust code). One Taichi kernel launch per time step: the stages are
separate top-level loops inside the kernel, which Taichi runs in order.

Two variants, both on one CPU thread:

* ``serial`` (default): every loop has ``ti.loop_config(serialize=True)``.
  The scatter-adds are then plain adds and Taichi fuses the whole step into a
  single serial task: the fastest way to run Taichi on one thread.
* ``parallel-atomic``: the idiomatic Taichi program (parallel loops, the
  scatter-adds compile to atomic adds), still run with one thread.  Shows
  the cost of atomics + parallel dispatch when there is nothing to gain.

``ti.init`` is called by :func:`init` (once per precision; it resets the
runtime, so build a new ``TaichiCloth`` after each call).
"""

# No "from __future__ import annotations": Taichi reads the annotations.
import numpy as np
import taichi as ti

import cloth_spec as spec

_current = None


def init(precision: str):
    """(Re)initialise Taichi: CPU, single thread, default float = precision."""
    global _current
    fp = ti.f64 if precision == "f64" else ti.f32
    ti.init(arch=ti.cpu, cpu_max_num_threads=1, default_fp=fp, random_seed=0, log_level=ti.WARN)
    _current = precision


@ti.data_oriented
class TaichiCloth:
    framework = "taichi"

    def __init__(self, cloth: spec.Cloth, precision: str, integrator: str, serial: bool = True):
        if _current != precision:
            init(precision)
        self.precision = precision
        self.integrator = integrator
        self.serial = serial
        self.variant = "serial" if serial else "parallel-atomic"
        self.cloth = cloth
        real = ti.f64 if precision == "f64" else ti.f32
        self.real = real
        n, s = spec.N_NODES, cloth.n_springs
        vec = ti.types.vector(3, real)

        def vfield():
            return ti.Vector.field(3, real, shape=n)

        self.x, self.v = vfield(), vfield()  # state
        self.xs, self.vs = vfield(), vfield()  # RK4 stage input
        self.acc = vfield()  # acceleration (force accumulator first)
        self.kx, self.kv = vfield(), vfield()  # RK4 weighted sums
        self.mass = ti.field(real, shape=n)
        self.free = ti.field(real, shape=n)
        self.sa = ti.field(ti.i32, shape=s)
        self.sb = ti.field(ti.i32, shape=s)
        self.rest = ti.field(real, shape=s)
        self.k = ti.field(real, shape=s)
        self.c = ti.field(real, shape=s)
        self.g = vec(*spec.GRAVITY)

        npf = np.float64 if precision == "f64" else np.float32
        self.mass.from_numpy(cloth.mass.astype(npf))
        self.free.from_numpy(cloth.free.astype(npf))
        self.sa.from_numpy(cloth.a)
        self.sb.from_numpy(cloth.b)
        self.rest.from_numpy(cloth.rest.astype(npf))
        self.k.from_numpy(cloth.k.astype(npf))
        self.c.from_numpy(cloth.c.astype(npf))
        self.reset()

    def reset(self):
        npf = np.float64 if self.precision == "f64" else np.float32
        self.x.from_numpy(self.cloth.x0.astype(npf))
        self.v.fill(0.0)

    # -- building blocks (inlined into the step kernels) ---------------------
    @ti.func
    def _accel(self, x: ti.template(), v: ti.template()):
        """self.acc = (F_springs + F_drag)/m + g, zero on pinned nodes."""
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(spec.N_NODES):
            self.acc[i] = ti.Vector([0.0, 0.0, 0.0])
        ti.loop_config(serialize=ti.static(self.serial))
        for e in range(self.sa.shape[0]):
            a, b = self.sa[e], self.sb[e]
            d = x[b] - x[a]
            length = d.norm()
            u = d / length
            s = self.k[e] * (length - self.rest[e]) + self.c[e] * (v[b] - v[a]).dot(u)
            fa = s * u
            self.acc[a] += fa
            self.acc[b] -= fa
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(spec.N_NODES):
            f = self.acc[i] - spec.DRAG * self.mass[i] * v[i]
            self.acc[i] = (f / self.mass[i] + self.g) * self.free[i]

    @ti.kernel
    def _euler_step(self):
        self._accel(self.x, self.v)
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(spec.N_NODES):
            self.v[i] += spec.DT * self.acc[i]
            self.x[i] += spec.DT * self.v[i]

    @ti.kernel
    def _rk4_step(self):
        dt = spec.DT
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(spec.N_NODES):
            self.xs[i] = self.x[i]
            self.vs[i] = self.v[i]
            self.kx[i] = ti.Vector([0.0, 0.0, 0.0])
            self.kv[i] = ti.Vector([0.0, 0.0, 0.0])
        for stage in ti.static(range(4)):
            w = ti.static((1.0, 2.0, 2.0, 1.0)[stage])
            # step fraction for the *next* stage's input
            h = ti.static((0.5, 0.5, 1.0, 0.0)[stage])
            self._accel(self.xs, self.vs)
            ti.loop_config(serialize=ti.static(self.serial))
            for i in range(spec.N_NODES):
                self.kx[i] += w * self.vs[i]
                self.kv[i] += w * self.acc[i]
                if ti.static(stage < 3):
                    xs_next = self.x[i] + (h * dt) * self.vs[i]
                    self.vs[i] = self.v[i] + (h * dt) * self.acc[i]
                    self.xs[i] = xs_next
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(spec.N_NODES):
            self.x[i] += (dt / 6.0) * self.kx[i]
            self.v[i] += (dt / 6.0) * self.kv[i]

    def step(self, n: int):
        kernel = self._euler_step if self.integrator == "euler" else self._rk4_step
        for _ in range(n):
            kernel()

    def sync(self):
        ti.sync()

    def state(self):
        return self.x.to_numpy().astype(np.float64), self.v.to_numpy().astype(np.float64)
