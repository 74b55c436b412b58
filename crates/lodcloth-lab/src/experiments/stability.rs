//! Longer studies built on the core. Pure library code: no files, no
//! printing; progress goes through a callback.

use std::sync::Arc;

use lodcloth_core::sim::{
    GridShape, Integrator, Loads, Material, Orientation, SimParams, Simulation, StabilityCheck, State, Topology,
};

/// Settings of a stability sweep.
#[derive(Debug, Clone)]
pub struct StabilitySweep {
    /// Square grid sizes (nodes per side).
    pub sizes: Vec<usize>,
    /// Multipliers of every K (raising k/m raises ω_max as √factor).
    pub stiffness_factors: Vec<f64>,
    /// Integrators to measure.
    pub integrators: Vec<Integrator>,
    /// Base material (C is kept; K is scaled).
    pub material: Material,
    /// Cloth side (m) and areal density (kg/m²): lumped masses.
    pub side: f64,
    pub areal_density: f64,
    /// Steps per trial run.
    pub steps: u32,
    /// Bisection iterations per threshold.
    pub bisections: u32,
}

/// One measured threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StabilityRow {
    pub integrator: Integrator,
    pub n: usize,
    pub stiffness_factor: f64,
    pub omega_gershgorin: f64,
    pub omega_max: f64,
    pub damping_rate: f64,
    /// Predicted limit on the top mode (∞: none, 0: unstable at any dt).
    pub predicted_dt: f64,
    /// Largest dt measured stable.
    pub measured_stable: f64,
    /// Smallest dt measured unstable (∞ when none was found up to the search cap).
    pub measured_unstable: f64,
}

impl StabilityRow {
    /// Threshold estimate: the middle of the final bracket (or its lower end when open).
    pub fn measured_dt(&self) -> f64 {
        if self.measured_unstable.is_finite() {
            0.5 * (self.measured_stable + self.measured_unstable)
        } else {
            self.measured_stable
        }
    }
}

/// A free cloth (no pins, gravity or drag) in its rest shape with a tiny
/// deterministic perturbation of every node, which excites every mode.
pub fn perturbed_free_cloth(
    n: usize,
    side: f64,
    areal_density: f64,
    material: Material,
    integrator: Integrator,
    dt: f64,
) -> Simulation {
    let shape = GridShape {
        nx: n,
        ny: n,
        width: side,
        height: side,
    };
    let topology = Arc::new(Topology::grid(shape, Orientation::Horizontal));
    let masses: Vec<f64> = topology.node_areas.iter().map(|a| a * areal_density).collect();
    let mut state = State::at_rest(&topology);
    let amplitude = 1e-4 * shape.hx();
    let mut seed = 0x2545_F491_4F6C_DD1Du64;
    for x in state.pos.iter_mut() {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        *x += amplitude * ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5);
    }
    let params = SimParams {
        dt,
        integrator,
        material,
        gravity: [0.0; 3],
        drag: 0.0,
        stiffness_adjustment: None,
        strain_limit: None,
        cg: Default::default(),
        self_contact: None,
    };
    Simulation::new(topology, masses, params, Loads::default(), state, StabilityCheck::Force)
        .expect("a generated free cloth is valid")
}

/// Run at least `steps` steps; unstable when a value turns non-finite, the
/// energy grows beyond 10⁴ times its start (amplitude ×100), or it more than
/// doubles over the second half of the run (a damped stable run loses energy).
///
/// Near its threshold explicit Euler's top mode grows by only ~ω²dt(dt − β)
/// per step, so the run is lengthened to 30/(ω_max·dt)² steps (at most 400k)
/// to give a slow growth time to show.
pub fn is_unstable(sim: &mut Simulation, steps: u32) -> bool {
    let wdt = sim.modal().omega_max * sim.params().dt;
    let steps = (steps as f64).max((30.0 / (wdt * wdt)).min(4e5)) as u32;
    let first = sim.step();
    let e0 = first.kinetic_energy + first.elastic_energy;
    let mut e_mid = f64::INFINITY;
    let mut e = e0;
    for s in 1..steps {
        let r = sim.step();
        e = r.kinetic_energy + r.elastic_energy;
        if !r.finite || e > 1e4 * e0 {
            return true;
        }
        if s == steps / 2 {
            e_mid = e;
        }
    }
    e > 2.0 * e_mid
}

/// Measure the stability threshold of every (integrator, size, stiffness)
/// combination by bisection and compare it with the prediction.
/// `progress(done, total)` is called after each combination.
pub fn stability_sweep(cfg: &StabilitySweep, progress: &mut dyn FnMut(usize, usize)) -> Vec<StabilityRow> {
    let total = cfg.integrators.len() * cfg.sizes.len() * cfg.stiffness_factors.len();
    let mut rows = Vec::with_capacity(total);
    for &integrator in &cfg.integrators {
        for &n in &cfg.sizes {
            for &factor in &cfg.stiffness_factors {
                let mut material = cfg.material;
                for s in material.springs.iter_mut() {
                    s.k *= factor;
                }
                let build = |dt: f64| perturbed_free_cloth(n, cfg.side, cfg.areal_density, material, integrator, dt);
                let modal = *build(1e-6).modal();
                let predicted = modal.dt_limit(integrator);
                // Bracket around the prediction; implicit Euler (no limit) is
                // probed up to 100× the symplectic limit.
                let reference = if predicted.is_finite() && predicted > 0.0 {
                    predicted
                } else {
                    modal.dt_limit(Integrator::SymplecticEuler)
                };
                let unstable = |dt: f64| is_unstable(&mut build(dt), cfg.steps);
                let (mut lo, mut hi) = (reference / 64.0, 4.0 * reference);
                if integrator.unconditionally_stable() {
                    hi = 100.0 * reference;
                }
                // (largest dt seen stable, smallest seen unstable)
                let (measured_stable, measured_unstable) = if unstable(lo) {
                    // Unstable even far below the reference: search downwards.
                    let mut h = lo;
                    while h > reference * 1e-4 && unstable(h) {
                        h /= 4.0;
                    }
                    (if unstable(h) { 0.0 } else { h }, lo)
                } else if !unstable(hi) {
                    (hi, f64::INFINITY)
                } else {
                    for _ in 0..cfg.bisections {
                        let mid = (lo * hi).sqrt();
                        if unstable(mid) {
                            hi = mid;
                        } else {
                            lo = mid;
                        }
                    }
                    (lo, hi)
                };
                let row = StabilityRow {
                    integrator,
                    n,
                    stiffness_factor: factor,
                    omega_gershgorin: modal.omega_gershgorin,
                    omega_max: modal.omega_max,
                    damping_rate: modal.damping_rate,
                    predicted_dt: predicted,
                    measured_stable,
                    measured_unstable,
                };
                rows.push(row);
                progress(rows.len(), total);
            }
        }
    }
    rows
}
