//! External loads and kinematic constraints, already resolved to node indices:
//! time profiles, forces on node sets, wind, and pins moving along paths.
//! The scene module builds these from config for a given resolution.

use std::f64::consts::TAU;

use super::topology::Topology;

/// A dimensionless time profile s(t) that scales a load.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Profile {
    /// s = 1.
    Constant,
    /// 0 before `start`, rising linearly to 1 at `end`, 1 after.
    Ramp {
        /// When the ramp starts (s).
        start: f64,
        /// When it reaches 1 (s).
        end: f64,
    },
    /// 1 for `start ≤ t < start + duration`, else 0.
    Pulse {
        /// When the pulse starts (s).
        start: f64,
        /// How long it lasts (s).
        duration: f64,
    },
    /// s = offset + amplitude · sin(2π·frequency·t + phase).
    Sine {
        /// Hz.
        frequency: f64,
        /// Radians.
        phase: f64,
        /// Dimensionless.
        amplitude: f64,
        /// Dimensionless.
        offset: f64,
    },
}

impl Profile {
    /// Value of the profile at time `t` (s).
    pub fn at(&self, t: f64) -> f64 {
        match *self {
            Profile::Constant => 1.0,
            Profile::Ramp { start, end } => {
                if t <= start {
                    0.0
                } else if t >= end {
                    1.0
                } else {
                    (t - start) / (end - start)
                }
            }
            Profile::Pulse { start, duration } => {
                if t >= start && t < start + duration {
                    1.0
                } else {
                    0.0
                }
            }
            Profile::Sine {
                frequency,
                phase,
                amplitude,
                offset,
            } => offset + amplitude * (TAU * frequency * t + phase).sin(),
        }
    }

    /// The largest |s(t)| over all t (what a stability bound must assume).
    pub fn max_abs(&self) -> f64 {
        match *self {
            Profile::Constant | Profile::Ramp { .. } | Profile::Pulse { .. } => 1.0,
            Profile::Sine { amplitude, offset, .. } => offset.abs() + amplitude.abs(),
        }
    }
}

/// A force on a set of nodes, `force · profile(t)` in total, split between
/// the nodes by `shares` (which sum to 1; the scene uses the nodes' areas, so
/// the same physical load acts at every resolution).
#[derive(Debug, Clone, PartialEq)]
pub struct NodeLoad {
    /// Loaded nodes.
    pub nodes: Vec<u32>,
    /// Fraction of the total force on each node.
    pub shares: Vec<f64>,
    /// Total force in newtons at profile value 1.
    pub force: [f64; 3],
    /// Time profile.
    pub profile: Profile,
}

/// A spring from one node to a point fixed in the world — Su et al.'s user
/// spring `k_r (r0 − s_i)` that pulls a surface by one point — with optional
/// damping against the node's velocity:
/// `F = profile(t) · (stiffness · (target − x) − damping · v)`.
/// A profile that drops to 0 releases the node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tether {
    /// The pulled node.
    pub node: u32,
    /// World point it is pulled towards (m).
    pub target: [f64; 3],
    /// Spring constant k_r (N/m, ≥ 0).
    pub stiffness: f64,
    /// Damping (N·s/m, ≥ 0).
    pub damping: f64,
    /// Time profile scaling both terms.
    pub profile: Profile,
}

/// Wind: quadratic aerodynamic drag on the normal component of the air
/// velocity relative to each node, F = ½ ρ C_d A |w_n| w_n n̂, with
/// w_n = (w − v)·n̂, A the node's rest area and n̂ its area-weighted normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wind {
    /// Air velocity (m/s) at profile value 1.
    pub velocity: [f64; 3],
    /// Time profile of the air velocity.
    pub profile: Profile,
    /// Air density ρ (kg/m³), 1.2 at sea level.
    pub air_density: f64,
    /// Drag coefficient C_d (dimensionless), about 1 for a flat plate.
    pub drag_coefficient: f64,
}

/// How a pinned node moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PinPath {
    /// Held at its anchor.
    Fixed,
    /// anchor + velocity·(clamp(t, start, end) − start): moves at constant
    /// velocity during [start, end], at rest before and after.
    Linear {
        /// Velocity while moving (m/s).
        velocity: [f64; 3],
        /// When it starts moving (s).
        start: f64,
        /// When it stops (s).
        end: f64,
    },
    /// anchor + amplitude · sin(2π·frequency·t): oscillates about the anchor.
    Sine {
        /// Largest offset from the anchor along each axis (m).
        amplitude: [f64; 3],
        /// Hz.
        frequency: f64,
    },
}

impl PinPath {
    /// Position offset from the anchor and velocity at time `t`.
    pub fn at(&self, t: f64) -> ([f64; 3], [f64; 3]) {
        match *self {
            PinPath::Fixed => ([0.0; 3], [0.0; 3]),
            PinPath::Linear { velocity, start, end } => {
                let tc = t.clamp(start, end) - start;
                let moving = t >= start && t < end;
                (velocity.map(|v| v * tc), if moving { velocity } else { [0.0; 3] })
            }
            PinPath::Sine { amplitude, frequency } => {
                let w = TAU * frequency;
                let (s, c) = (w * t).sin_cos();
                (amplitude.map(|a| a * s), amplitude.map(|a| a * w * c))
            }
        }
    }
}

/// A node whose position is prescribed: it feels no force and follows its path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pin {
    /// Node index.
    pub node: u32,
    /// Position at t = 0 (and for a fixed pin, always).
    pub anchor: [f64; 3],
    /// Motion relative to the anchor.
    pub path: PinPath,
}

impl Pin {
    /// Prescribed position and velocity at time `t`.
    pub fn at(&self, t: f64) -> ([f64; 3], [f64; 3]) {
        let (d, v) = self.path.at(t);
        ([self.anchor[0] + d[0], self.anchor[1] + d[1], self.anchor[2] + d[2]], v)
    }
}

/// A hand on the cloth: a spring from a patch of the cloth to a point in the
/// world, with damping against the patch's velocity. The patch is given by
/// node `weights` (summing to 1; the touch layer makes them the patch's
/// consistent nodal weights, so their first moment is the same material
/// point at every level). With x̄ = Σ wᵢ xᵢ and v̄ = Σ wᵢ vᵢ the patch's
/// position and velocity, the force is `F = stiffness · (target − x̄) −
/// damping · v̄`, and node i carries wᵢ·F: the total is F and its moment
/// acts at x̄ at every resolution.
#[derive(Debug, Clone, PartialEq)]
pub struct Grab {
    /// Nodes of the patch.
    pub nodes: Vec<u32>,
    /// Each node's weight (summing to 1).
    pub weights: Vec<f64>,
    /// Where the patch is pulled to (m).
    pub target: [f64; 3],
    /// Spring constant (N/m, ≥ 0).
    pub stiffness: f64,
    /// Damping (N·s/m, ≥ 0).
    pub damping: f64,
}

impl Grab {
    /// The patch's position and velocity, Σ wᵢ xᵢ and Σ wᵢ vᵢ (SoA fields).
    pub fn patch(&self, pos: &[f64], vel: &[f64]) -> ([f64; 3], [f64; 3]) {
        let n = pos.len() / 3;
        let mut x = [0.0; 3];
        let mut v = [0.0; 3];
        for (&k, &w) in self.nodes.iter().zip(&self.weights) {
            for c in 0..3 {
                x[c] += w * pos[c * n + k as usize];
                v[c] += w * vel[c * n + k as usize];
            }
        }
        (x, v)
    }

    /// The total force at (pos, vel).
    pub fn force(&self, pos: &[f64], vel: &[f64]) -> [f64; 3] {
        let (x, v) = self.patch(pos, vel);
        [0, 1, 2].map(|c| self.stiffness * (self.target[c] - x[c]) - self.damping * v[c])
    }

    /// Add each node's share of the force to `f` (SoA).
    pub(crate) fn add_force(&self, pos: &[f64], vel: &[f64], f: &mut [f64]) {
        let n = pos.len() / 3;
        let total = self.force(pos, vel);
        for (&k, &w) in self.nodes.iter().zip(&self.weights) {
            for c in 0..3 {
                f[c * n + k as usize] += w * total[c];
            }
        }
    }
}

/// A live move of pinned nodes on top of their scripted path: the offset
/// goes linearly from `from` at `start` to `to` at `end` (simulated s) and
/// stays there, so a pin never jumps (its velocity is the ramp's slope).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PinShift {
    /// Offset at `start` and before (m).
    pub from: [f64; 3],
    /// Offset at `end` and after (m).
    pub to: [f64; 3],
    /// When the move starts (s).
    pub start: f64,
    /// When it ends (s, > start unless from = to).
    pub end: f64,
}

impl PinShift {
    /// Offset and velocity at time `t`.
    pub fn at(&self, t: f64) -> ([f64; 3], [f64; 3]) {
        if t >= self.end || self.end <= self.start {
            return (self.to, [0.0; 3]);
        }
        if t <= self.start {
            return (self.from, [0.0; 3]);
        }
        let span = self.end - self.start;
        let s = (t - self.start) / span;
        (
            [0, 1, 2].map(|c| self.from[c] + s * (self.to[c] - self.from[c])),
            [0, 1, 2].map(|c| (self.to[c] - self.from[c]) / span),
        )
    }

    /// True when the offset is zero from `t` on.
    pub fn is_rest_from(&self, t: f64) -> bool {
        self.to == [0.0; 3] && (t >= self.end || self.from == [0.0; 3])
    }
}

/// All external influences on a cloth except gravity and drag.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Loads {
    /// Forces on node sets.
    pub forces: Vec<NodeLoad>,
    /// Optional wind.
    pub wind: Option<Wind>,
    /// Pinned nodes (at most one pin per node).
    pub pins: Vec<Pin>,
    /// Springs from nodes to world points. Their energy is not part of
    /// [`StepReport`](super::StepReport)'s elastic energy.
    pub tethers: Vec<Tether>,
    /// Rigid bodies the free nodes cannot enter (see [`super::contact`]).
    pub colliders: Vec<super::contact::Collider>,
}

impl Loads {
    /// True when [`Loads::add_forces`] adds anything (forces, tethers or wind).
    pub(crate) fn adds_forces(&self) -> bool {
        !self.forces.is_empty() || !self.tethers.is_empty() || self.wind.is_some()
    }

    /// Add the scene forces and the wind force at (t, pos, vel) to `f` (SoA).
    /// `normals` is scratch of length 3n when there is wind (unused otherwise).
    pub(crate) fn add_forces(
        &self,
        topology: &Topology,
        t: f64,
        pos: &[f64],
        vel: &[f64],
        f: &mut [f64],
        normals: &mut [f64],
    ) {
        let n = topology.n_nodes;
        for load in &self.forces {
            let s = load.profile.at(t);
            for (&k, &share) in load.nodes.iter().zip(&load.shares) {
                for c in 0..3 {
                    f[c * n + k as usize] += share * s * load.force[c];
                }
            }
        }
        for tether in &self.tethers {
            let s = tether.profile.at(t);
            if s == 0.0 {
                continue;
            }
            let k = tether.node as usize;
            for c in 0..3 {
                let (x, v) = (pos[c * n + k], vel[c * n + k]);
                f[c * n + k] += s * (tether.stiffness * (tether.target[c] - x) - tether.damping * v);
            }
        }
        if let Some(wind) = &self.wind {
            node_normals(topology, pos, normals);
            let s = wind.profile.at(t);
            let half_rho_cd = 0.5 * wind.air_density * wind.drag_coefficient;
            for k in 0..n {
                let nk = [normals[k], normals[n + k], normals[2 * n + k]];
                let rel = [
                    s * wind.velocity[0] - vel[k],
                    s * wind.velocity[1] - vel[n + k],
                    s * wind.velocity[2] - vel[2 * n + k],
                ];
                let wn = rel[0] * nk[0] + rel[1] * nk[1] + rel[2] * nk[2];
                let mag = half_rho_cd * topology.node_areas[k] * wn.abs() * wn;
                for c in 0..3 {
                    f[c * n + k] += mag * nk[c];
                }
            }
        }
    }
}

/// Area-weighted node normals (unit length; zero for nodes with no area).
/// `normals` has the same [x…, y…, z…] layout as positions.
pub(crate) fn node_normals(topology: &Topology, pos: &[f64], normals: &mut [f64]) {
    let n = topology.n_nodes;
    normals.fill(0.0);
    let p = |k: u32, c: usize| pos[c * n + k as usize];
    for tri in &topology.triangles {
        let [a, b, c] = *tri;
        let u = [p(b, 0) - p(a, 0), p(b, 1) - p(a, 1), p(b, 2) - p(a, 2)];
        let w = [p(c, 0) - p(a, 0), p(c, 1) - p(a, 1), p(c, 2) - p(a, 2)];
        // Cross product = twice the triangle's area times its unit normal.
        let cr = [
            u[1] * w[2] - u[2] * w[1],
            u[2] * w[0] - u[0] * w[2],
            u[0] * w[1] - u[1] * w[0],
        ];
        for k in [a, b, c] {
            for d in 0..3 {
                normals[d * n + k as usize] += cr[d];
            }
        }
    }
    for k in 0..n {
        let l = (normals[k].powi(2) + normals[n + k].powi(2) + normals[2 * n + k].powi(2)).sqrt();
        let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
        for d in 0..3 {
            normals[d * n + k] *= inv;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_and_pulse_have_the_documented_shape() {
        let r = Profile::Ramp { start: 1.0, end: 3.0 };
        assert_eq!(r.at(0.5), 0.0);
        assert!((r.at(2.0) - 0.5).abs() < 1e-15);
        assert_eq!(r.at(4.0), 1.0);
        let p = Profile::Pulse {
            start: 1.0,
            duration: 0.5,
        };
        assert_eq!([p.at(0.99), p.at(1.0), p.at(1.49), p.at(1.5)], [0.0, 1.0, 1.0, 0.0]);
    }

    #[test]
    fn pin_velocity_is_the_derivative_of_its_position() {
        let paths = [
            PinPath::Linear {
                velocity: [0.1, -0.2, 0.3],
                start: 0.5,
                end: 2.0,
            },
            PinPath::Sine {
                amplitude: [0.05, 0.0, -0.02],
                frequency: 1.5,
            },
        ];
        let h = 1e-6;
        for path in paths {
            for t in [0.7, 1.1, 1.9] {
                let (p1, _) = path.at(t + h);
                let (p0, _) = path.at(t - h);
                let (_, v) = path.at(t);
                for c in 0..3 {
                    assert!(((p1[c] - p0[c]) / (2.0 * h) - v[c]).abs() < 1e-6);
                }
            }
        }
    }
}
