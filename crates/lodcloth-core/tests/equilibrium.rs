//! Static equilibrium: a hanging chain or cloth with drag settles where every
//! free node's spring forces balance its weight. Checked against Hooke's law
//! (analytic extensions of a chain), against force balance (residual
//! acceleration ≈ 0, pins carry the whole weight), and across integrators
//! (the rest state does not depend on how it was reached).

use crate::common;

use std::sync::Arc;

use common::{build, dist, fixed_pins, grid, lumped_masses, material, pairs_topology, params};
use lodcloth::sim::{Integrator, Loads, Orientation, Simulation, SpringKind, StabilityCheck, State};

const G: f64 = 9.81;

/// Largest |acceleration| over free nodes (pins report 0).
fn largest_acceleration(sim: &mut Simulation) -> f64 {
    let n = sim.topology().n_nodes;
    let a = sim.accelerations();
    (0..n)
        .map(|k| (a[k] * a[k] + a[n + k] * a[n + k] + a[2 * n + k] * a[2 * n + k]).sqrt())
        .fold(0.0, f64::max)
}

#[test]
fn hanging_spring_chain_settles_at_hooke_extensions_of_the_weight_below_each_spring() {
    // Node 0 pinned at the origin, nodes 1..5 hanging below it, each of mass m:
    // spring j (from node j to j+1) carries the weight of the N−1−j nodes below,
    // so its length is L0 + (N−1−j) m g / k.
    const NODES: usize = 6;
    let (l0, k, m) = (0.1, 10.0, 0.02);
    let rest: Vec<[f64; 3]> = (0..NODES).map(|j| [0.0, -(j as f64) * l0, 0.0]).collect();
    let pairs: Vec<(u32, u32)> = (0..NODES as u32 - 1).map(|j| (j, j + 1)).collect();
    let topo = pairs_topology(rest, &pairs, SpringKind::Structural);
    for integrator in [Integrator::SymplecticEuler, Integrator::Rk4, Integrator::ImplicitEuler] {
        let mut p = params(2e-3, integrator, material((k, 0.05), (0.0, 0.0), (0.0, 0.0)));
        p.gravity = [0.0, -G, 0.0];
        p.drag = 5.0;
        let loads = Loads {
            pins: fixed_pins(&topo, &[0]),
            ..Loads::default()
        };
        let topo = Arc::new(topo.clone());
        let mut sim = build(
            topo.clone(),
            vec![m; NODES],
            p,
            loads,
            State::at_rest(&topo),
            StabilityCheck::Enforce,
        );
        common::run(&mut sim, 5000);
        let mut worst: f64 = 0.0;
        for j in 0..NODES - 1 {
            let l = dist(sim.state().position(j), sim.state().position(j + 1));
            let expected = l0 + (NODES - 1 - j) as f64 * m * G / k;
            worst = worst.max((l - expected).abs() / (expected - l0));
        }
        // Nothing moves sideways.
        let sideways = (0..NODES).map(|j| sim.state().position(j)[0].abs()).fold(0.0, f64::max);
        let residual = largest_acceleration(&mut sim) / G;
        eprintln!("{integrator}: chain extensions off by {worst:.2e} (relative), residual |a|/g {residual:.2e}");
        assert!(worst < 1e-8, "{integrator}: extension error {worst:e}");
        assert!(residual < 1e-8, "{integrator}: residual {residual:e}");
        assert_eq!(sideways, 0.0);
    }
}

const N: usize = 6;
const SIZE: f64 = 0.3;

/// A 6×6 vertical cloth pinned at its two top corners, with drag, settled.
fn settled_cloth(integrator: Integrator, dt: f64, steps: usize) -> Simulation {
    let topo = grid(N, N, SIZE, SIZE, Orientation::Vertical);
    let masses = lumped_masses(&topo, 0.2);
    let mut p = params(dt, integrator, material((50.0, 0.01), (10.0, 0.002), (2.0, 0.0004)));
    p.gravity = [0.0, -G, 0.0];
    p.drag = 8.0;
    let loads = Loads {
        pins: fixed_pins(&topo, &[0, N - 1]),
        ..Loads::default()
    };
    let mut sim = build(
        topo.clone(),
        masses,
        p,
        loads,
        State::at_rest(&topo),
        StabilityCheck::Enforce,
    );
    common::run(&mut sim, steps);
    sim
}

#[test]
fn hanging_cloth_settles_to_rest_with_residual_acceleration_far_below_g() {
    let mut sim = settled_cloth(Integrator::SymplecticEuler, 1e-3, 5000);
    let residual = largest_acceleration(&mut sim) / G;
    let speed = (0..N * N)
        .map(|k| common::norm(sim.state().velocity(k)))
        .fold(0.0, f64::max);
    let sag = -sim.state().position(N * N - 1)[1] - SIZE;
    eprintln!(
        "symplectic euler, 5000 steps of 1 ms: residual |a|/g {residual:.2e}, largest speed {speed:.2e} m/s, \
         bottom corner {sag:.4} m below its rest height"
    );
    assert!(sag > 1e-3, "the cloth did not sag: the test would measure nothing");
    assert!(residual < 1e-8, "residual acceleration {residual:e} g");
}

#[test]
fn pins_of_a_settled_cloth_carry_its_whole_weight() {
    let sim = settled_cloth(Integrator::SymplecticEuler, 1e-3, 5000);
    // Spring forces on the two pins, evaluated directly from the state.
    let f = common::scalar_spring_forces(sim.topology(), &sim.params().material, f64::INFINITY, sim.state());
    let on_pins = [0, 1, 2].map(|c| f[0][c] + f[N - 1][c]);
    let free_weight: f64 = sim.masses()[1..N - 1].iter().chain(&sim.masses()[N..]).sum::<f64>() * G;
    eprintln!("springs pull the pins by {on_pins:?} N; free weight {free_weight:.6} N");
    // The springs pull the pins down by exactly the weight they hold up.
    assert!(
        (on_pins[1] + free_weight).abs() < 1e-6 * free_weight,
        "{on_pins:?} vs {free_weight}"
    );
    assert!(on_pins[0].abs() < 1e-6 * free_weight && on_pins[2].abs() < 1e-6 * free_weight);
    // By symmetry each pin carries half.
    assert!((f[0][1] - f[N - 1][1]).abs() < 1e-6 * free_weight);
}

#[test]
fn implicit_euler_rk4_and_symplectic_euler_settle_to_the_same_equilibrium() {
    let reference = settled_cloth(Integrator::SymplecticEuler, 1e-3, 5000);
    for (integrator, dt, steps) in [(Integrator::Rk4, 2e-3, 2500), (Integrator::ImplicitEuler, 1e-2, 500)] {
        let mut sim = settled_cloth(integrator, dt, steps);
        let d = sim.state().max_distance(reference.state());
        let residual = largest_acceleration(&mut sim) / G;
        eprintln!("{integrator} (dt {dt}): largest distance from symplectic Euler's equilibrium {d:.2e} m, residual |a|/g {residual:.2e}");
        assert!(d < 1e-9 * SIZE, "{integrator}: {d} m apart");
    }
}
