//! Convergence order on a smooth problem: a small cloth pinned at its two top
//! corners falls from horizontal under gravity (spring damping and a little
//! drag, no strain control). Each integrator's end state at T = 0.25 s is
//! compared with an RK4 run at a much finer step; when dt halves the error of
//! a p-th order method falls by 2^p.
//!
//! Step sizes are powers of two so every run lands exactly on T.

use crate::common;

use std::sync::Arc;

use common::{build, fixed_pins, grid, lumped_masses, material, params};
use lodcloth::sim::{Integrator, Loads, Material, Orientation, StabilityCheck, State, Topology};

// (structural, shear, bend) coefficients: C = 5e-4 s × K damps the top mesh
// mode enough that explicit Euler is stable at every dt used here.

const T: f64 = 0.25;
const NX: usize = 6;

/// (structural, shear, bend) coefficients: C = 5e-4 s × K damps the top mesh
/// mode enough that explicit Euler is stable at every dt used here.
fn fabric() -> Material {
    material((20.0, 0.01), (5.0, 0.0025), (1.0, 0.0005))
}

fn end_state(topology: &Arc<Topology>, integrator: Integrator, dt: f64) -> State {
    let mut p = params(dt, integrator, fabric());
    p.gravity = [0.0, -9.81, 0.0];
    p.drag = 0.5;
    let loads = Loads {
        pins: fixed_pins(topology, &[0, NX - 1]),
        ..Loads::default()
    };
    let masses = lumped_masses(topology, 0.2);
    let mut sim = build(
        topology.clone(),
        masses,
        p,
        loads,
        State::at_rest(topology),
        StabilityCheck::Enforce,
    );
    let steps = (T / dt).round() as usize;
    assert_eq!(steps as f64 * dt, T, "dt must divide T exactly");
    common::run(&mut sim, steps);
    assert_eq!(sim.state().time, T);
    sim.state().clone()
}

fn topology() -> Arc<Topology> {
    grid(NX, NX, 0.5, 0.5, Orientation::Horizontal)
}

/// Errors at dt, dt/2, dt/4 against the fine RK4 reference, and the two ratios.
fn errors(integrator: Integrator, dt0: f64) -> ([f64; 3], [f64; 2]) {
    let topo = topology();
    let reference = end_state(&topo, Integrator::Rk4, 2f64.powi(-16));
    let e: Vec<f64> = (0..3)
        .map(|i| end_state(&topo, integrator, dt0 / 2f64.powi(i)).max_distance(&reference))
        .collect();
    let errs = [e[0], e[1], e[2]];
    let ratios = [errs[0] / errs[1], errs[1] / errs[2]];
    eprintln!(
        "{integrator}: dt {dt0:.3e}, /2, /4: errors {:.3e} {:.3e} {:.3e}, ratios {:.2} {:.2}",
        errs[0], errs[1], errs[2], ratios[0], ratios[1]
    );
    (errs, ratios)
}

/// ω_max·dt of the cloth at step `dt`, from the library's modal estimate.
fn omega_dt(dt: f64) -> f64 {
    let topo = topology();
    let p = params(dt, Integrator::Rk4, fabric());
    let sim = build(
        topo.clone(),
        lumped_masses(&topo, 0.2),
        p,
        Loads {
            pins: fixed_pins(&topo, &[0, NX - 1]),
            ..Loads::default()
        },
        State::at_rest(&topo),
        StabilityCheck::Enforce,
    );
    sim.modal().omega_max * dt
}

#[test]
fn rk4_error_falls_16x_when_dt_halves() {
    let dt0 = 2f64.powi(-9);
    eprintln!("rk4 largest ω_max·dt = {:.2}", omega_dt(dt0));
    let (errs, ratios) = errors(Integrator::Rk4, dt0);
    assert!(
        errs[2] > 1e-13,
        "finest error {:e} is at round-off level: the test measures nothing",
        errs[2]
    );
    for r in ratios {
        assert!((12.0..20.0).contains(&r), "RK4 ratio {r}, expected ~16");
    }
}

#[test]
fn symplectic_euler_error_falls_2x_when_dt_halves() {
    let (_, ratios) = errors(Integrator::SymplecticEuler, 2f64.powi(-12));
    for r in ratios {
        assert!((1.7..2.3).contains(&r), "symplectic Euler ratio {r}, expected ~2");
    }
}

#[test]
fn explicit_euler_error_falls_2x_when_dt_halves() {
    let (_, ratios) = errors(Integrator::ExplicitEuler, 2f64.powi(-12));
    for r in ratios {
        assert!((1.7..2.3).contains(&r), "explicit Euler ratio {r}, expected ~2");
    }
}

#[test]
fn implicit_euler_error_falls_2x_when_dt_halves() {
    let (_, ratios) = errors(Integrator::ImplicitEuler, 2f64.powi(-12));
    for r in ratios {
        assert!((1.7..2.3).contains(&r), "implicit Euler ratio {r}, expected ~2");
    }
}

/// XPBD with one sweep per step solves backward Euler only in part, but
/// what it leaves shrinks with the step: it must still converge at first
/// order to the same trajectory.
#[test]
fn xpbd_error_falls_2x_when_dt_halves() {
    let (_, ratios) = errors(Integrator::Xpbd, 2f64.powi(-12));
    for r in ratios {
        assert!((1.7..2.3).contains(&r), "XPBD ratio {r}, expected ~2");
    }
}

/// A spring whose top end is driven sinusoidally (a moving pin) and whose
/// free end also feels a sinusoidal load: RK4 must keep its order with
/// time-dependent constraints and loads (its stages sit at t, t + dt/2, t + dt).
fn driven_end_state(integrator: Integrator, dt: f64) -> State {
    use lodcloth::sim::{NodeLoad, Pin, PinPath, Profile, SpringKind};
    let topo = Arc::new(common::pairs_topology(
        vec![[0.0, 0.0, 0.0], [0.0, -0.2, 0.0]],
        &[(0, 1)],
        SpringKind::Structural,
    ));
    let loads = Loads {
        forces: vec![NodeLoad {
            nodes: vec![1],
            shares: vec![1.0],
            force: [0.05, 0.0, 0.02],
            profile: Profile::Sine {
                frequency: 1.5,
                phase: 0.0,
                amplitude: 1.0,
                offset: 0.0,
            },
        }],
        pins: vec![Pin {
            node: 0,
            anchor: [0.0; 3],
            path: PinPath::Sine {
                amplitude: [0.03, 0.02, 0.0],
                frequency: 2.0,
            },
        }],
        ..Loads::default()
    };
    let mut p = params(dt, integrator, common::uniform_material(20.0, 0.05));
    p.gravity = [0.0, -9.81, 0.0];
    let mut sim = build(
        topo.clone(),
        vec![0.05, 0.05],
        p,
        loads,
        State::at_rest(&topo),
        StabilityCheck::Enforce,
    );
    let steps = (T / dt).round() as usize;
    common::run(&mut sim, steps);
    sim.state().clone()
}

#[test]
fn rk4_error_falls_16x_when_dt_halves_with_a_moving_pin_and_a_time_varying_load() {
    let reference = driven_end_state(Integrator::Rk4, 2f64.powi(-16));
    let errs: Vec<f64> = (9..12)
        .map(|k| driven_end_state(Integrator::Rk4, 2f64.powi(-k)).max_distance(&reference))
        .collect();
    let ratios = [errs[0] / errs[1], errs[1] / errs[2]];
    eprintln!(
        "rk4, driven spring: errors {:.3e} {:.3e} {:.3e}, ratios {:.2} {:.2}",
        errs[0], errs[1], errs[2], ratios[0], ratios[1]
    );
    assert!(
        errs[2] > 1e-13,
        "finest error {:e} is at round-off level: the test measures nothing",
        errs[2]
    );
    for r in ratios {
        assert!((12.0..20.0).contains(&r), "RK4 ratio {r}, expected ~16");
    }
}
