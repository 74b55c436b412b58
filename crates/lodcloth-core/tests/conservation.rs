//! Spring forces are internal and central (Newton's third law, force along
//! the spring): on a free cloth with no gravity, drag or pins, total momentum
//! Σ m v never changes, and without forces off the spring axis the angular
//! momentum Σ m x × v about the origin is conserved too.

use crate::common;

use common::{angular_momentum, build, cross, grid, lumped_masses, momentum, norm, params, uniform_material, Rng};
use lodcloth::sim::{Integrator, Loads, Material, Orientation, Simulation, StabilityCheck, State};

const N: usize = 8;
const SIZE: f64 = 0.4;

/// A free 8×8 cloth, perturbed (±5% of the spacing), moving with random node
/// velocities plus a drift and a spin, so both momenta are far from zero.
fn free_cloth(integrator: Integrator, material: Material, dt_fraction: f64) -> (Simulation, Vec<f64>) {
    let topo = grid(N, N, SIZE, SIZE, Orientation::Horizontal);
    let masses = lumped_masses(&topo, 0.2);
    let mut rng = Rng::new(7);
    let h = SIZE / (N - 1) as f64;
    let mut state = common::perturbed_state(&topo, &mut rng, 0.05 * h, 0.05);
    let (drift, spin) = ([0.03, -0.02, 0.05], [0.3, 1.1, -0.4]);
    for k in 0..topo.n_nodes {
        let w = cross(spin, state.position(k));
        let v = state.velocity(k);
        state.set_velocity(k, [0, 1, 2].map(|c| v[c] + drift[c] + w[c]));
    }
    // dt as a fraction of the integrator's predicted limit (symplectic Euler's for RK4 too).
    let probe = build(
        topo.clone(),
        masses.clone(),
        params(1e-6, Integrator::SymplecticEuler, material),
        Loads::default(),
        state.clone(),
        StabilityCheck::Enforce,
    );
    let dt = dt_fraction * probe.dt_limit();
    let sim = build(
        topo,
        masses.clone(),
        params(dt, integrator, material),
        Loads::default(),
        state,
        StabilityCheck::Enforce,
    );
    (sim, masses)
}

/// Σ m |v|: the scale against which momentum changes are judged.
fn momentum_scale(state: &State, masses: &[f64]) -> f64 {
    masses
        .iter()
        .enumerate()
        .map(|(k, m)| m * norm(state.velocity(k)))
        .sum()
}

/// Σ m |x × v|: the scale for angular momentum.
fn angular_scale(state: &State, masses: &[f64]) -> f64 {
    masses
        .iter()
        .enumerate()
        .map(|(k, m)| m * norm(cross(state.position(k), state.velocity(k))))
        .sum()
}

/// Largest change of `quantity` over `steps`, relative to `scale` at the start.
fn largest_drift(
    sim: &mut Simulation,
    masses: &[f64],
    steps: usize,
    quantity: fn(&State, &[f64]) -> [f64; 3],
    scale: fn(&State, &[f64]) -> f64,
) -> f64 {
    let q0 = quantity(sim.state(), masses);
    let s0 = scale(sim.state(), masses);
    let mut worst: f64 = 0.0;
    for _ in 0..steps {
        assert!(sim.step().finite);
        let q = quantity(sim.state(), masses);
        worst = worst.max(norm([q[0] - q0[0], q[1] - q0[1], q[2] - q0[2]]) / s0);
    }
    worst
}

#[test]
fn total_momentum_of_a_free_damped_cloth_is_constant_to_1e12_with_symplectic_euler_rk4_and_explicit_euler() {
    // Spring damping is internal too: include it.
    let material = uniform_material(50.0, 0.02);
    for integrator in [Integrator::SymplecticEuler, Integrator::Rk4, Integrator::ExplicitEuler] {
        // Explicit Euler is stable here thanks to the damping at a small dt.
        let fraction = if integrator == Integrator::ExplicitEuler {
            0.02
        } else {
            0.5
        };
        let (mut sim, masses) = free_cloth(integrator, material, fraction);
        let drift = largest_drift(&mut sim, &masses, 3000, momentum, momentum_scale);
        eprintln!("{integrator}: largest relative momentum change over 3000 steps {drift:.2e}");
        assert!(drift < 1e-12, "{integrator}: momentum changed by {drift:e} (relative)");
    }
}

#[test]
fn angular_momentum_of_a_free_undamped_cloth_is_exactly_conserved_by_symplectic_euler() {
    // Symplectic Euler: L₁ = Σ m (x₀ + dt v₁) × v₁ = Σ m x₀ × v₁ = L₀ + dt Σ x₀ × F(x₀),
    // and central forces have no net torque: conserved up to round-off.
    let (mut sim, masses) = free_cloth(Integrator::SymplecticEuler, uniform_material(50.0, 0.0), 0.5);
    let drift = largest_drift(&mut sim, &masses, 3000, angular_momentum, angular_scale);
    eprintln!("symplectic euler: largest relative angular momentum change {drift:.2e}");
    assert!(drift < 1e-12, "angular momentum changed by {drift:e} (relative)");
}

#[test]
fn angular_momentum_drift_of_rk4_is_small_and_falls_with_dt_to_the_fourth() {
    // RK4 conserves linear invariants exactly but angular momentum (quadratic)
    // only to its order: the drift falls ~16x when dt halves.
    let mut drifts = Vec::new();
    for fraction in [0.4, 0.2] {
        let (mut sim, masses) = free_cloth(Integrator::Rk4, uniform_material(50.0, 0.0), fraction);
        let steps = (3000.0 * 0.4 / fraction) as usize;
        drifts.push(largest_drift(&mut sim, &masses, steps, angular_momentum, angular_scale));
    }
    let ratio = drifts[0] / drifts[1];
    eprintln!(
        "rk4: angular momentum drift {:.2e} at dt, {:.2e} at dt/2 (same time span): ratio {ratio:.1}",
        drifts[0], drifts[1]
    );
    assert!(drifts[0] < 2e-4, "drift {:e}", drifts[0]);
    assert!(ratio > 8.0, "drift ratio {ratio}");
}
