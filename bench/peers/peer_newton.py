"""NVIDIA Newton (warp-lang) cloth on the CPU device.

Newton is float32 only and its ``SolverSemiImplicit`` is symplectic Euler
(v1 = v0 + a dt, x1 = x0 + v1 dt), so only that integrator is run.
The cloth is built from particles and springs (no triangles, no contacts):

* Newton's spring kernel is the same formula as ours (``eval_spring``:
  F = (K (L - L0) + C dL/dt) along the spring).
* Pinned nodes are zero-mass particles (inverse mass 0: Newton's integrator
  then leaves them unmoved and ignores gravity for them).
* Newton has no global drag, so a small Warp kernel writes
  F = -drag * m * v into ``state.particle_f`` before each solver step (it
  also replaces ``state.clear_forces()``).
* Particle-particle contact is switched off (``model.particle_grid = None``,
  zero particle radius).

Warp's CPU backend runs every kernel on the calling thread, so this is
single-threaded without further settings.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_WARNING  # no init banner / kernel-cache chatter

import newton  # noqa: E402
import cloth_spec as spec  # noqa: E402


@wp.kernel
def _drag_force(v: wp.array[wp.vec3], mass: wp.array[float], drag: float, f: wp.array[wp.vec3]):
    tid = wp.tid()
    f[tid] = -drag * mass[tid] * v[tid]


class NewtonCloth:
    framework = "newton"
    variant = "SolverSemiImplicit"

    def __init__(self, cloth: spec.Cloth, precision: str, integrator: str):
        if precision != "f32" or integrator != "euler":
            raise ValueError("Newton: only f32 symplectic Euler")
        self.precision, self.integrator = precision, integrator
        self.device = wp.get_device("cpu")
        builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=spec.GRAVITY)
        pinned = set(spec.PINNED)
        for k in range(spec.N_NODES):
            m = 0.0 if k in pinned else float(cloth.mass[k])
            builder.add_particle(tuple(cloth.x0[k]), (0.0, 0.0, 0.0), m, radius=0.0)
        for a, b, ke, kd in zip(cloth.a, cloth.b, cloth.k, cloth.c):
            builder.add_spring(int(a), int(b), float(ke), float(kd), 0.0)
        self.model = builder.finalize(device=self.device)
        self.model.particle_grid = None
        assert self.model.spring_count == cloth.n_springs
        # the true masses (pinned too) for the drag force; drag on a pinned
        # node is irrelevant since its inverse mass is 0
        self.mass = wp.array(cloth.mass.astype(np.float32), dtype=float, device=self.device)
        self.solver = newton.solvers.SolverSemiImplicit(self.model)
        self.control = self.model.control()
        self.s0, self.s1 = self.model.state(), self.model.state()
        self.x0 = self.s0.particle_q.numpy().copy()
        self.reset()

    def reset(self):
        for s in (self.s0, self.s1):
            s.particle_q.assign(self.x0)
            s.particle_qd.zero_()

    def step(self, n: int):
        for _ in range(n):
            wp.launch(
                _drag_force,
                dim=spec.N_NODES,
                inputs=[self.s0.particle_qd, self.mass, spec.DRAG],
                outputs=[self.s0.particle_f],
                device=self.device,
            )
            self.solver.step(self.s0, self.s1, self.control, None, spec.DT)
            self.s0, self.s1 = self.s1, self.s0

    def sync(self):
        wp.synchronize_device(self.device)

    def state(self):
        return (
            self.s0.particle_q.numpy().astype(np.float64),
            self.s0.particle_qd.numpy().astype(np.float64),
        )
