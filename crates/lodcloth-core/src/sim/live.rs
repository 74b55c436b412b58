//! Changes a client makes to a running cloth between steps: grabs, the
//! wind, pin moves and impulses. Each may allocate when it is made (inputs
//! arrive at most a few thousand times a second); none allocates in a step.
//! The touch layer ([`crate::touch`]) turns inputs given in material
//! coordinates into these, at whatever level the cloth runs.

use super::loads::{Grab, PinShift, Wind};
use super::params::Integrator;
use super::stability::dt_limit;
use super::{check_node_shares, invalid, SimError, Simulation};

/// Whether a set of grabs keeps a cloth stable at its dt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GrabHeadroom {
    /// The cloth's time step (s).
    pub dt: f64,
    /// Predicted largest stable dt with the grabs (s).
    pub limit: f64,
}

impl GrabHeadroom {
    /// True when the grabs leave the cloth stable at its dt.
    pub fn stable(&self) -> bool {
        self.dt <= self.limit
    }
}

impl Simulation {
    /// The grabs in force.
    pub fn grabs(&self) -> &[Grab] {
        &self.model.grabs
    }

    /// Replace the grabs. Each must name existing nodes with finite weights,
    /// a finite target and finite stiffness and damping ≥ 0. Stability is
    /// the caller's to check ([`Simulation::grab_headroom`]).
    pub fn set_grabs(&mut self, grabs: Vec<Grab>) -> Result<(), SimError> {
        let n = self.model.topology.n_nodes;
        for (i, g) in grabs.iter().enumerate() {
            check_node_shares(&g.nodes, &g.weights, n, "grab", "grab weights")?;
            let values = g.weights.iter().chain(&g.target).chain([&g.stiffness, &g.damping]);
            if let Some(&x) = values.clone().find(|x| !x.is_finite()) {
                return Err(invalid(
                    format!("grabs[{i}]"),
                    x,
                    "grab weights, target, stiffness and damping must be finite",
                ));
            }
            if g.stiffness < 0.0 || g.damping < 0.0 {
                return Err(invalid(
                    format!("grabs[{i}]"),
                    g.stiffness.min(g.damping),
                    "grab stiffness and damping must be ≥ 0",
                ));
            }
        }
        self.model.grabs = grabs;
        self.invalidate();
        Ok(())
    }

    /// Predicted largest stable dt with `grabs` added to the cloth's own
    /// springs. A grab adds k·w wᵀ to the stiffness matrix (c·w wᵀ to the
    /// damping), whose M^{-1/2}-scaled norm is k·Σ wᵢ²/mᵢ over free nodes;
    /// by Weyl's inequality ω_max² and the damping rates grow by at most the
    /// sum of these over the grabs, and the limit is the integrator's for
    /// that mode. Implicit Euler takes external forces, grabs included,
    /// explicitly: its limit is symplectic Euler's on the grabs alone.
    pub fn grab_headroom(&self, grabs: &[Grab]) -> GrabHeadroom {
        let m = &self.model;
        let (mut dk, mut dc) = (0.0, 0.0);
        for g in grabs {
            let s: f64 = g
                .nodes
                .iter()
                .zip(&g.weights)
                .map(|(&k, &w)| w * w * m.inv_mass[k as usize])
                .sum();
            dk += g.stiffness * s;
            dc += g.damping * s;
        }
        let dt = m.params.dt;
        let limit = match m.params.integrator {
            Integrator::ImplicitEuler | Integrator::Xpbd => dt_limit(Integrator::SymplecticEuler, dk.sqrt(), dc),
            integrator => {
                let mut modal = self.modal;
                modal.omega_max = (modal.omega_max.powi(2) + dk).sqrt();
                modal.damping_rate += dc;
                modal.damped_omega = (modal.damped_omega.powi(2) + dk).sqrt();
                modal.damped_rate += dc;
                modal.damped_rate_bound += dc;
                modal.dt_limit(integrator)
            }
        };
        GrabHeadroom { dt, limit }
    }

    /// The largest stiffness (N/m) one more grab on `grab`'s patch, with its
    /// damping, may have beside `others` and stay stable; 0 when none is.
    pub fn max_grab_stiffness(&self, grab: &Grab, others: &[Grab]) -> f64 {
        let mut all: Vec<Grab> = others.to_vec();
        all.push(Grab {
            stiffness: 0.0,
            ..grab.clone()
        });
        let stable_with = |all: &mut Vec<Grab>, k: f64| {
            if let Some(last) = all.last_mut() {
                last.stiffness = k;
            }
            self.grab_headroom(all).stable()
        };
        if !stable_with(&mut all, 0.0) {
            return 0.0;
        }
        let mut hi = 1.0;
        while stable_with(&mut all, hi) {
            hi *= 2.0;
            if hi > 1e15 {
                return f64::INFINITY;
            }
        }
        let mut lo = hi / 2.0;
        if !stable_with(&mut all, lo) {
            lo = 0.0;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if stable_with(&mut all, mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// Set (or with `None` remove) the wind from now on. Its values must be
    /// finite and its density and drag coefficient ≥ 0.
    pub fn set_wind(&mut self, wind: Option<Wind>) -> Result<(), SimError> {
        if let Some(w) = &wind {
            let all = w.velocity.iter().chain([&w.air_density, &w.drag_coefficient]);
            if let Some(&x) = all.clone().find(|x| !x.is_finite()) {
                return Err(invalid("wind", x, "wind values must be finite"));
            }
            if w.air_density < 0.0 || w.drag_coefficient < 0.0 {
                return Err(invalid(
                    "wind",
                    w.air_density.min(w.drag_coefficient),
                    "air density and drag coefficient must be ≥ 0",
                ));
            }
            let n3 = 3 * self.model.topology.n_nodes;
            if self.ws.normals.len() != n3 {
                self.ws.normals = vec![0.0; n3];
            }
        }
        self.model.loads.wind = wind;
        self.invalidate();
        Ok(())
    }

    /// Move the pins at `pins` (indices into [`Loads::pins`](super::Loads))
    /// by `shift` on top of their scripted paths; a later shift of a pin
    /// replaces its earlier one.
    pub fn shift_pins(&mut self, pins: &[usize], shift: PinShift) -> Result<(), SimError> {
        let count = self.model.loads.pins.len();
        if let Some(&i) = pins.iter().find(|&&i| i >= count) {
            return Err(invalid("pin", i as f64, "no such pin"));
        }
        let values = shift.from.iter().chain(&shift.to).chain([&shift.start, &shift.end]);
        if let Some(&x) = values.clone().find(|x| !x.is_finite()) {
            return Err(invalid("pin shift", x, "pin shifts must be finite"));
        }
        if self.model.pin_shifts.len() != count {
            self.model.pin_shifts = vec![PinShift::default(); count];
        }
        for &i in pins {
            self.model.pin_shifts[i] = shift;
        }
        self.apply_pins();
        self.invalidate();
        Ok(())
    }

    /// The live shift of pin `i` (zero when it was never moved).
    pub fn pin_shift(&self, i: usize) -> PinShift {
        self.model.pin_shifts.get(i).copied().unwrap_or_default()
    }

    /// Every live pin shift, one per pin (empty when none was ever moved).
    pub fn pin_shifts(&self) -> &[PinShift] {
        &self.model.pin_shifts
    }

    /// Give the cloth the impulse `impulse` (N·s) at once, shared by `nodes`
    /// in proportion to `weights` (summing to 1): node i's velocity changes
    /// by wᵢ·J/mᵢ. Shares on pinned nodes go into their supports.
    pub fn add_impulse(&mut self, nodes: &[u32], weights: &[f64], impulse: [f64; 3]) -> Result<(), SimError> {
        let n = self.model.topology.n_nodes;
        check_node_shares(nodes, weights, n, "impulse", "impulse weights")?;
        if let Some(&x) = weights.iter().chain(&impulse).find(|x| !x.is_finite()) {
            return Err(invalid("impulse", x, "impulse and weights must be finite"));
        }
        for (&k, &w) in nodes.iter().zip(weights) {
            let inv = self.model.inv_mass[k as usize];
            for c in 0..3 {
                self.state.vel[c * n + k as usize] += w * impulse[c] * inv;
            }
        }
        self.invalidate();
        Ok(())
    }
}
