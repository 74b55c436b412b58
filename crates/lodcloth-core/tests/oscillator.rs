//! A single spring between a pinned node and a free mass is a harmonic
//! oscillator: the free node moves along the spring with period 2π√(m/k).
//! The period is measured from zero crossings of the elongation.

use crate::common;

use std::f64::consts::TAU;
use std::sync::Arc;

use common::{build, fixed_pins, pairs_topology, params, uniform_material};
use lodcloth::sim::{Integrator, Loads, Simulation, SpringKind, StabilityCheck, State};

/// Spring direction (a unit vector off the axes, so all three components move).
const DIR: [f64; 3] = [1.0 / 3.0, 2.0 / 3.0, -2.0 / 3.0];
const L0: f64 = 0.5;
const K: f64 = 250.0;
const M: f64 = 0.4;
const AMPLITUDE: f64 = 0.02;

/// Node 0 pinned at the origin, node 1 (mass M) at L0 along DIR, released
/// from rest stretched by AMPLITUDE.
fn oscillator(integrator: Integrator, dt: f64) -> Simulation {
    let rest = vec![[0.0; 3], DIR.map(|d| d * L0)];
    let topology = pairs_topology(rest, &[(0, 1)], SpringKind::Structural);
    let loads = Loads {
        pins: fixed_pins(&topology, &[0]),
        ..Loads::default()
    };
    let mut state = State::at_rest(&topology);
    state.set_position(1, DIR.map(|d| d * (L0 + AMPLITUDE)));
    let p = params(dt, integrator, uniform_material(K, 0.0));
    build(Arc::new(topology), vec![M, M], p, loads, state, StabilityCheck::Enforce)
}

/// Signed elongation along the spring's rest direction.
fn elongation(sim: &Simulation) -> f64 {
    let x = sim.state().position(1);
    x[0] * DIR[0] + x[1] * DIR[1] + x[2] * DIR[2] - L0
}

/// Amplitude of the harmonic motion through the current state: √(s² + (ṡ/ω)²).
fn amplitude(sim: &Simulation) -> f64 {
    let v = sim.state().velocity(1);
    let sdot = v[0] * DIR[0] + v[1] * DIR[1] + v[2] * DIR[2];
    elongation(sim).hypot(sdot / (K / M).sqrt())
}

/// Mean period from upward zero crossings (linear interpolation between steps)
/// over `periods` expected periods, and the amplitude at the end.
fn measure_period(sim: &mut Simulation, periods: f64) -> (f64, f64) {
    let expected = TAU * (M / K).sqrt();
    let dt = sim.params().dt;
    let steps = (periods * expected / dt).ceil() as usize;
    let mut crossings = Vec::new();
    let mut prev = (0.0, elongation(sim));
    for _ in 0..steps {
        let r = sim.step();
        assert!(r.finite);
        let s = elongation(sim);
        if prev.1 < 0.0 && s >= 0.0 {
            crossings.push(prev.0 + dt * (-prev.1) / (s - prev.1));
        }
        prev = (r.time, s);
    }
    assert!(crossings.len() >= 5, "only {} crossings", crossings.len());
    let period = (crossings[crossings.len() - 1] - crossings[0]) / (crossings.len() - 1) as f64;
    (period, amplitude(sim))
}

#[test]
fn rk4_single_spring_oscillates_with_period_two_pi_sqrt_m_over_k_within_half_a_percent() {
    let omega = (K / M).sqrt();
    let expected = TAU / omega;
    // ω·dt = 0.2: about 31 steps per period, well inside RK4's limit of 2.83.
    let dt = 0.2 / omega;
    let mut sim = oscillator(Integrator::Rk4, dt);
    let (period, amplitude) = measure_period(&mut sim, 20.0);
    let err = (period - expected) / expected;
    let amp_err = (amplitude - AMPLITUDE) / AMPLITUDE;
    eprintln!(
        "rk4, ω·dt = 0.2: period {period:.6} s vs 2π√(m/k) = {expected:.6} s, error {:.2e}; amplitude after 20 periods off by {:.2e}",
        err, amp_err
    );
    assert!(err.abs() < 5e-3, "period error {err:e}");
    // The free node moves along the spring only: amplitude kept to 0.5% too.
    assert!(amp_err.abs() < 5e-3, "amplitude error {amp_err:e}");
}

#[test]
fn symplectic_euler_single_spring_period_is_2pi_sqrt_m_over_k_within_its_order_dt_squared_bound() {
    let omega = (K / M).sqrt();
    let expected = TAU / omega;
    for theta in [0.2, 0.05] {
        let dt = theta / omega;
        let mut sim = oscillator(Integrator::SymplecticEuler, dt);
        let (period, amplitude) = measure_period(&mut sim, 20.0);
        let err = (period - expected) / expected;
        // Symplectic Euler's discrete frequency is (2/dt)·asin(ω dt / 2): the
        // period is short by about (ω dt)²/24. Allow twice that.
        let bound = theta * theta / 12.0;
        eprintln!(
            "symplectic euler, ω·dt = {theta}: period error {err:.3e} (bound {bound:.2e}), amplitude {:.5} vs {AMPLITUDE}",
            amplitude
        );
        assert!(err.abs() < bound, "period error {err:e} beyond {bound:e}");
        // No energy drift: the amplitude stays within O(ω dt) of the initial one.
        assert!((amplitude - AMPLITUDE).abs() < theta * AMPLITUDE);
    }
}

#[test]
fn symplectic_euler_period_error_shrinks_fourfold_when_dt_halves() {
    let omega = (K / M).sqrt();
    let expected = TAU / omega;
    let errs: Vec<f64> = [0.4, 0.2]
        .iter()
        .map(|&theta| {
            let mut sim = oscillator(Integrator::SymplecticEuler, theta / omega);
            let (period, _) = measure_period(&mut sim, 20.0);
            (period - expected) / expected
        })
        .collect();
    let ratio = errs[0] / errs[1];
    eprintln!(
        "symplectic euler period errors {:.3e}, {:.3e}: ratio {ratio:.2}",
        errs[0], errs[1]
    );
    // Second order in the period (first order in the trajectory): ratio ≈ 4.
    assert!((3.5..4.5).contains(&ratio), "ratio {ratio}");
}
