//! Energy behaviour of the integrators on a small cloth: undamped symplectic
//! Euler keeps the energy bounded (it conserves a nearby "shadow" energy),
//! undamped explicit Euler gains energy, damping dissipates it, and implicit
//! Euler dissipates it even without damping.
//!
//! Energies come from the step report and are cross-checked once against a
//! direct evaluation of ½mv² + ½K(L−L0)² − m g·x.

use crate::common;

use common::{build, fixed_pins, grid, lumped_masses, params, perturbed_state, uniform_material, Rng};
use lodcloth::sim::{Integrator, Loads, Material, Orientation, Simulation, StabilityCheck, State, StepReport};

const N: usize = 6;
const SIZE: f64 = 0.3;
const DENSITY: f64 = 0.2;

/// A free 6×6 cloth (no gravity), perturbed by `dx` (fraction of the spacing)
/// with random velocities, at `fraction` of symplectic Euler's predicted limit.
fn free_cloth(integrator: Integrator, material: Material, drag: f64, dx: f64, fraction: f64) -> Simulation {
    let topo = grid(N, N, SIZE, SIZE, Orientation::Horizontal);
    let masses = lumped_masses(&topo, DENSITY);
    let h = SIZE / (N - 1) as f64;
    let state = perturbed_state(&topo, &mut Rng::new(11), dx * h, dx * 0.5);
    let mut p = params(
        1e-6,
        Integrator::SymplecticEuler,
        uniform_material(material.springs[0].k, 0.0),
    );
    let probe = build(
        topo.clone(),
        masses.clone(),
        p,
        Loads::default(),
        state.clone(),
        StabilityCheck::Force,
    );
    p = params(fraction * probe.dt_limit(), integrator, material);
    p.drag = drag;
    build(topo, masses, p, Loads::default(), state, StabilityCheck::Force)
}

/// Reports of `steps` steps.
fn reports(sim: &mut Simulation, steps: usize) -> Vec<StepReport> {
    (0..steps)
        .map(|_| {
            let r = sim.step();
            assert!(r.finite, "diverged at step {}", r.step);
            r
        })
        .collect()
}

/// Total energies after each of `steps` steps.
fn energies(sim: &mut Simulation, steps: usize) -> Vec<f64> {
    reports(sim, steps).iter().map(StepReport::total_energy).collect()
}

fn initial_energy(sim: &Simulation) -> f64 {
    let p = sim.params();
    let free = vec![true; sim.topology().n_nodes];
    common::scalar_total_energy(sim.topology(), &p.material, sim.masses(), &free, p.gravity, sim.state())
}

#[test]
fn reported_energy_equals_half_m_v2_plus_half_k_stretch2_minus_m_g_x() {
    let mut sim = free_cloth(Integrator::SymplecticEuler, uniform_material(40.0, 0.0), 0.0, 0.1, 0.5);
    let r = common::run(&mut sim, 10);
    let direct = initial_energy(&sim);
    let elastic = common::scalar_elastic_energy(sim.topology(), &sim.params().material, sim.state());
    assert!(
        (r.total_energy() - direct).abs() <= 1e-12 * direct,
        "{} vs {direct}",
        r.total_energy()
    );
    assert!((r.elastic_energy - elastic).abs() <= 1e-12 * elastic);
}

#[test]
fn undamped_symplectic_euler_keeps_energy_bounded_over_1e5_steps() {
    let fraction = 0.1;
    let mut sim = free_cloth(
        Integrator::SymplecticEuler,
        uniform_material(40.0, 0.0),
        0.0,
        0.05,
        fraction,
    );
    // ω_max·dt: symplectic Euler's limit is ω dt = 2.
    let theta = 2.0 * fraction;
    let e0 = initial_energy(&sim);
    let e = energies(&mut sim, 100_000);
    let (early, all) = (deviation(&e[..10_000], e0), deviation(&e, e0));
    let drift = mean_drift(&e, 10_000) / e0;
    eprintln!(
        "symplectic euler, free cloth, ω_max dt = {theta}, 1e5 steps: largest |E − E0|/E0 {early:.2e} in the first 1e4 steps, \
         {all:.2e} over all; drift of the mean {drift:.2e}"
    );
    // The measured energy oscillates about the conserved shadow energy by up
    // to ~ω dt/2 of each mode's share; it must not grow.
    assert!(all < theta, "energy strayed by {all}");
    assert!(
        all < 2.0 * early.max(1e-3),
        "energy deviation grew from {early} to {all}"
    );
    assert!(drift.abs() < 0.01, "energy drifted by {drift}");
}

/// Largest |E − E0| over `e`.
fn deviation(e: &[f64], e0: f64) -> f64 {
    e.iter().map(|x| (x - e0).abs()).fold(0.0, f64::max) / e0.abs().max(f64::MIN_POSITIVE)
}

/// Mean over the last `window` values minus mean over the first `window`.
fn mean_drift(e: &[f64], window: usize) -> f64 {
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    mean(&e[e.len() - window..]) - mean(&e[..window])
}

#[test]
fn undamped_symplectic_euler_keeps_energy_of_a_falling_pinned_cloth_bounded_over_1e5_steps() {
    let topo = grid(N, N, SIZE, SIZE, Orientation::Horizontal);
    let masses = lumped_masses(&topo, DENSITY);
    let loads = Loads {
        pins: fixed_pins(&topo, &[0, N - 1]),
        ..Loads::default()
    };
    let mut p = params(1e-6, Integrator::SymplecticEuler, uniform_material(40.0, 0.0));
    let probe = build(
        topo.clone(),
        masses.clone(),
        p,
        loads.clone(),
        State::at_rest(&topo),
        StabilityCheck::Enforce,
    );
    p.dt = 0.1 * probe.dt_limit();
    p.gravity = [0.0, -9.81, 0.0];
    let mut sim = build(
        topo.clone(),
        masses.clone(),
        p,
        loads,
        State::at_rest(&topo),
        StabilityCheck::Enforce,
    );
    // Starts at rest at y = 0: E0 = 0. Scale: the weight times the cloth size.
    let scale = masses.iter().sum::<f64>() * 9.81 * SIZE;
    let r = reports(&mut sim, 100_000);
    let e: Vec<f64> = r.iter().map(StepReport::total_energy).collect();
    let most_kinetic = r.iter().map(|r| r.kinetic_energy).fold(0.0, f64::max) / scale;
    let early = e[..10_000].iter().map(|x| x.abs()).fold(0.0, f64::max) / scale;
    let all = e.iter().map(|x| x.abs()).fold(0.0, f64::max) / scale;
    let drift = mean_drift(&e, 10_000) / scale;
    eprintln!(
        "symplectic euler, falling cloth, 1e5 steps ({:.1} s): largest |E − E0| {early:.2e} M g L in the first 1e4 steps, \
         {all:.2e} over all; drift of the mean {drift:.2e} M g L; largest kinetic energy {most_kinetic:.2} M g L",
        sim.state().time
    );
    assert!(
        most_kinetic > 0.1,
        "the cloth hardly moved: the test would measure nothing"
    );
    // Energy moves from the swing into faster modes over the run, whose
    // oscillation about the shadow energy is larger: bounded, not constant.
    assert!(all < 0.01, "energy strayed by {all} M g L");
    assert!(drift.abs() < 0.005, "energy drifted by {drift} M g L");
}

#[test]
fn undamped_explicit_euler_gains_energy_at_every_step() {
    // Small amplitude: linear regime, where every mode's energy grows by
    // 1 + (ω dt)² per step, so the total can only grow.
    let mut sim = free_cloth(Integrator::ExplicitEuler, uniform_material(40.0, 0.0), 0.0, 1e-4, 0.05);
    let e0 = initial_energy(&sim);
    let e = energies(&mut sim, 1000);
    let mut prev = e0;
    for (i, &x) in e.iter().enumerate() {
        assert!(
            x >= prev * (1.0 - 1e-12),
            "energy fell at step {}: {prev} -> {x}",
            i + 1
        );
        prev = x;
    }
    let gain = e[e.len() - 1] / e0;
    eprintln!("explicit euler, 1000 steps at 0.05 x the symplectic limit: energy x{gain:.3}");
    assert!(gain > 1.1, "energy only grew by {gain}");
}

#[test]
fn damping_dissipates_energy_at_every_step_with_rk4() {
    // Spring damping and drag: dE/dt = −γ Σ m v² − Σ C (Δv·u)² ≤ 0.
    let mut sim = free_cloth(Integrator::Rk4, uniform_material(40.0, 0.01), 0.5, 0.1, 0.2);
    let e0 = initial_energy(&sim);
    let e = energies(&mut sim, 5000);
    let mut prev = e0;
    for (i, &x) in e.iter().enumerate() {
        assert!(x <= prev, "energy rose at step {}: {prev} -> {x}", i + 1);
        prev = x;
    }
    let left = e[e.len() - 1] / e0;
    eprintln!("rk4 with damping, 5000 steps: energy fell to {left:.3e} of its start");
    assert!(left < 0.5);
}

#[test]
fn damping_dissipates_energy_with_symplectic_euler() {
    let mut sim = free_cloth(Integrator::SymplecticEuler, uniform_material(40.0, 0.01), 0.5, 0.1, 0.2);
    let e0 = initial_energy(&sim);
    let e = energies(&mut sim, 5000);
    // Symplectic Euler's measured energy wiggles by O(ω dt) within a step, but
    // each block of 500 steps ends lower than it started.
    let mut prev = e0;
    for block in e.chunks(500) {
        let last = block[block.len() - 1];
        assert!(last < prev, "energy rose over a block: {prev} -> {last}");
        prev = last;
    }
    let left = e[e.len() - 1] / e0;
    eprintln!("symplectic euler with damping, 5000 steps: energy fell to {left:.3e} of its start");
    assert!(left < 0.5);
}

#[test]
fn undamped_implicit_euler_loses_energy() {
    // Backward Euler multiplies each linear mode's energy by 1/(1 + (ω dt)²).
    let mut sim = free_cloth(Integrator::ImplicitEuler, uniform_material(40.0, 0.0), 0.0, 1e-3, 2.0);
    let e0 = initial_energy(&sim);
    let e = energies(&mut sim, 500);
    let mut prev = e0;
    for (i, &x) in e.iter().enumerate() {
        assert!(x <= prev * (1.0 + 1e-9), "energy rose at step {}: {prev} -> {x}", i + 1);
        prev = x;
    }
    let left = e[e.len() - 1] / e0;
    eprintln!("implicit euler without damping, 500 steps at 2x the symplectic limit: energy fell to {left:.3e}");
    assert!(left < 0.5);
}
