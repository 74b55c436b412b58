//! XPBD against independent truths: one spring is backward Euler exactly
//! (the recursion solved by hand here), a cloth's error against a fine RK4
//! run falls linearly with dt, and a hanging cloth comes to rest where the
//! springs' forces balance gravity.

use crate::common;

use std::sync::Arc;

use common::{build, fixed_pins, pairs_topology, params, uniform_material};
use lodcloth::sim::{Integrator, Loads, SpringKind, StabilityCheck, State};

/// Node 0 pinned at the origin, node 1 of mass `M` hanging below it on a
/// spring (K, C) under gravity, released stretched by 3 cm and moving.
const K: f64 = 250.0;
const C: f64 = 0.8;
const M: f64 = 0.4;
const L0: f64 = 0.5;
const G: f64 = 9.81;

#[test]
fn one_spring_is_backward_euler_to_rounding() {
    // ω·dt = √(K/M)·dt ≈ 0.1.
    let dt = 4e-3;
    let topology = pairs_topology(vec![[0.0; 3], [0.0, -L0, 0.0]], &[(0, 1)], SpringKind::Structural);
    let mut state = State::at_rest(&topology);
    state.set_position(1, [0.0, -L0 - 0.03, 0.0]);
    state.set_velocity(1, [0.0, 0.2, 0.0]);
    let mut p = params(dt, Integrator::Xpbd, uniform_material(K, C));
    p.gravity = [0.0, -G, 0.0];
    let loads = Loads {
        pins: fixed_pins(&topology, &[0]),
        ..Loads::default()
    };
    let mut sim = build(Arc::new(topology), vec![M, M], p, loads, state, StabilityCheck::Enforce);
    // Backward Euler for the elongation e = −y − L0 and its rate:
    // e₁ = e₀ + h·ė₁, M·ė₁ = M·ė₀ + h·(M·g − K·e₁ − C·ė₁), solved for ė₁.
    let (mut e, mut de) = (0.03, -0.2);
    let mut largest: f64 = 0.0;
    for _ in 0..2000 {
        de = (M * de + dt * (M * G - K * e)) / (M + dt * C + dt * dt * K);
        e += dt * de;
        let r = sim.step();
        assert!(r.finite);
        let (y, vy) = (sim.state().position(1)[1], sim.state().velocity(1)[1]);
        largest = largest.max((-y - L0 - e).abs()).max((-vy - de).abs() * dt);
        let x = sim.state().position(1);
        assert!(x[0] == 0.0 && x[2] == 0.0, "the motion left the spring's line: {x:?}");
    }
    // The free oscillation is damped by backward Euler too: it settles at
    // the static stretch M·g/K.
    assert!(
        (e - M * G / K).abs() < 1e-3 * M * G / K,
        "the recursion did not settle: {e}"
    );
    assert!(largest < 1e-14, "XPBD left backward Euler by {largest:e} m");
}

#[test]
fn a_pure_damper_and_a_stiff_spring_stay_finite() {
    // K = 0 (the compliance is infinite) and K = 1e9 N/m at a step 10⁴ times
    // the explicit limit: the correction is written to stay finite in both.
    for k in [0.0, 1e9] {
        let topology = pairs_topology(vec![[0.0; 3], [0.0, -L0, 0.0]], &[(0, 1)], SpringKind::Structural);
        let mut p = params(1e-2, Integrator::Xpbd, uniform_material(k, 0.5));
        p.gravity = [0.0, -G, 0.0];
        let mut sim = build(
            Arc::new(topology.clone()),
            vec![M, M],
            p,
            Loads {
                pins: fixed_pins(&topology, &[0]),
                ..Loads::default()
            },
            State::at_rest(&topology),
            StabilityCheck::Enforce,
        );
        let r = common::run(&mut sim, 200);
        assert!(r.finite, "K = {k}: diverged");
        let y = sim.state().position(1)[1];
        if k > 0.0 {
            // Static stretch 4e-9 m: the node hangs at the rest length.
            assert!((y + L0).abs() < 1e-6, "K = {k}: hangs at {y}");
        } else {
            // A damper alone holds nothing: the node falls, slowed by C.
            assert!(y < -L0 - 1.0, "K = 0: only fell to {y}");
        }
    }
}
