//! A mirror-symmetric scene stays mirror symmetric, and the same input gives
//! bit-identical output.
//!
//! Mirror: node (i, j) ↔ (nx−1−i, j), with x ↔ width − x and vx ↔ −vx; y, z
//! and their velocities equal. The grid's springs (both shear diagonals) and
//! node masses are mirror symmetric, so only round-off can break the symmetry.

use crate::common;

use std::path::Path;

use common::build;
use lodcloth::scene::Scene;
use lodcloth::sim::{Integrator, Loads, Orientation, Simulation, StabilityCheck, State, StrainLimit};

const NX: usize = 10;
const NY: usize = 8;
const WIDTH: f64 = 0.45;

/// A horizontal 10×8 cloth pinned at its two top corners, falling under
/// gravity, at 0.3 × symplectic Euler's predicted limit.
fn corners_pinned(integrator: Integrator, strain_limit: Option<StrainLimit>) -> Simulation {
    let topo = common::grid(NX, NY, WIDTH, 0.35, Orientation::Horizontal);
    let masses = common::lumped_masses(&topo, 0.2);
    let material = common::material((60.0, 0.006), (10.0, 0.001), (1.0, 0.0001));
    let loads = Loads {
        pins: common::fixed_pins(&topo, &[0, NX - 1]),
        ..Loads::default()
    };
    let mut p = common::params(1e-6, Integrator::SymplecticEuler, material);
    let probe = build(
        topo.clone(),
        masses.clone(),
        p,
        loads.clone(),
        State::at_rest(&topo),
        StabilityCheck::Enforce,
    );
    p.dt = 0.3 * probe.dt_limit();
    p.integrator = integrator;
    p.gravity = [0.0, -9.81, 0.0];
    p.drag = 0.2;
    p.strain_limit = strain_limit;
    build(
        topo.clone(),
        masses,
        p,
        loads,
        State::at_rest(&topo),
        StabilityCheck::Enforce,
    )
}

/// Largest violation of the mirror symmetry in positions (m) and velocities (m/s).
fn asymmetry(state: &State, nx: usize, ny: usize, width: f64) -> (f64, f64) {
    let (mut dx, mut dv): (f64, f64) = (0.0, 0.0);
    for j in 0..ny {
        for i in 0..nx {
            let (a, b) = (j * nx + i, j * nx + (nx - 1 - i));
            let (pa, pb) = (state.position(a), state.position(b));
            let (va, vb) = (state.velocity(a), state.velocity(b));
            dx = dx
                .max((pa[0] - (width - pb[0])).abs())
                .max((pa[1] - pb[1]).abs())
                .max((pa[2] - pb[2]).abs());
            dv = dv
                .max((va[0] + vb[0]).abs())
                .max((va[1] - vb[1]).abs())
                .max((va[2] - vb[2]).abs());
        }
    }
    (dx, dv)
}

/// Run `steps` steps and check the mirror symmetry after each one.
///
/// Round-off (~1e-16) seeds an asymmetry that a draping cloth amplifies: its
/// folds are physically unstable to asymmetric perturbations, and the seed
/// grows ~10x per 200 steps here. A real symmetry bug (a wrong stencil index,
/// an order-dependent limiter) shows at once, so the test checks both: round-off
/// level for the first 100 steps, and ≤ 1e-9 of the cloth's size (positions)
/// or top speed (velocities) over a run long enough to fall, swing and fold.
fn assert_stays_symmetric(mut sim: Simulation, steps: usize, label: &str) {
    let shape = sim.topology().grid.expect("grid");
    let n = shape.nx * shape.ny;
    let (mut dx_max, mut dv_max, mut early): (f64, f64, f64) = (0.0, 0.0, 0.0);
    let (mut fell, mut speed): (f64, f64) = (0.0, 0.0);
    for step in 1..=steps {
        assert!(sim.step().finite, "{label} diverged");
        let (dx, dv) = asymmetry(sim.state(), shape.nx, shape.ny, shape.width);
        dx_max = dx_max.max(dx);
        dv_max = dv_max.max(dv);
        if step <= 100 {
            early = early.max(dx);
        }
        let s = sim.state();
        fell = fell.max(s.pos[n..2 * n].iter().fold(0.0, |m, y| y.abs().max(m)));
        speed = speed.max((0..n).map(|k| common::norm(s.velocity(k))).fold(0.0, f64::max));
    }
    eprintln!(
        "{label}: {steps} steps ({:.2} s): asymmetry {early:.1e} m in the first 100 steps, at most {dx_max:.2e} m \
         and {dv_max:.2e} m/s over the run; cloth fell {fell:.3} m, top speed {speed:.2} m/s",
        sim.state().time
    );
    assert!(fell > 0.1 * shape.height, "{label}: the cloth hardly moved");
    assert!(early < 1e-14, "{label}: asymmetry {early:e} m within 100 steps");
    assert!(dx_max < 1e-9 * shape.width, "{label}: position asymmetry {dx_max:e} m");
    assert!(dv_max < 1e-9 * speed, "{label}: velocity asymmetry {dv_max:e} m/s");
}

#[test]
fn cloth_pinned_at_both_top_corners_stays_mirror_symmetric_with_every_integrator() {
    for integrator in [Integrator::SymplecticEuler, Integrator::Rk4, Integrator::ImplicitEuler] {
        assert_stays_symmetric(corners_pinned(integrator, None), 2000, integrator.name());
    }
}

#[test]
fn cloth_pinned_at_both_top_corners_stays_mirror_symmetric_under_strain_limiting() {
    let limit = StrainLimit {
        max_strain: 0.01,
        ..StrainLimit::default()
    };
    let sim = corners_pinned(Integrator::SymplecticEuler, Some(limit));
    let mut corrected = 0;
    let probe = &mut sim.clone();
    for _ in 0..1200 {
        corrected += probe.step().strain_iterations;
    }
    assert!(corrected > 0, "the limiter never acted: the test would measure nothing");
    assert_stays_symmetric(sim, 1200, "symplectic_euler + strain limit");
}

#[test]
fn hanging_scene_stays_mirror_symmetric_at_12x12() {
    let mut scene = Scene::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/scenes/hanging.toml"
    )))
    .expect("shipped scene loads");
    let probe = scene.build_at(12, 12).expect("builds");
    scene.params.dt = 0.5 * probe.dt_limit();
    assert_stays_symmetric(
        scene.build_at(12, 12).expect("builds"),
        2000,
        "hanging.toml at 12x12 (strain-limited)",
    );
}

fn bits(state: &State) -> Vec<u64> {
    state
        .pos
        .iter()
        .chain(&state.vel)
        .map(|x| x.to_bits())
        .chain([state.time.to_bits(), state.step])
        .collect()
}

#[test]
fn the_same_input_run_twice_gives_bit_identical_states() {
    let mut cases: Vec<(String, Simulation)> = Vec::new();
    for integrator in lodcloth::sim::Integrator::ALL {
        let mut scene = Scene::load(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../config/scenes/paper-2-corner.toml"
        )))
        .expect("shipped scene loads");
        scene.params.integrator = integrator;
        scene.stability = StabilityCheck::Force;
        cases.push((
            format!("paper-2-corner, {integrator}"),
            scene.build_at(16, 16).expect("builds"),
        ));
    }
    let limited = corners_pinned(
        Integrator::Rk4,
        Some(StrainLimit {
            max_strain: 0.01,
            ..StrainLimit::default()
        }),
    );
    cases.push(("corners pinned, rk4 + strain limit".into(), limited));
    for (label, template) in cases {
        let (mut a, mut b) = (template.clone(), template);
        for _ in 0..1500 {
            let (ra, rb) = (a.step(), b.step());
            assert_eq!(ra.total_energy().to_bits(), rb.total_energy().to_bits(), "{label}");
        }
        assert!(bits(a.state()) == bits(b.state()), "{label}: runs differ");
        // And a clone taken mid-run continues identically.
        let mut c = a.clone();
        for _ in 0..100 {
            a.step();
            c.step();
        }
        assert!(bits(a.state()) == bits(c.state()), "{label}: clone differs");
    }
}

#[test]
fn simulations_built_twice_from_the_same_scene_are_bit_identical() {
    let scene = Scene::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/scenes/paper-3-left-edge.toml"
    )))
    .expect("shipped scene loads");
    let mut scene = scene.clone();
    scene.params.dt = 1e-3;
    scene.params.integrator = Integrator::ImplicitEuler;
    let (mut a, mut b) = (
        scene.build_at(16, 16).expect("builds"),
        scene.build_at(16, 16).expect("builds"),
    );
    common::run(&mut a, 1500);
    common::run(&mut b, 1500);
    assert!(bits(a.state()) == bits(b.state()));
}

/// A cloth rebuilt in the middle of a run (the daemon does so when it gets
/// new coefficients) and given the run's state continues bit for bit, step
/// times included: the times of later steps count from the run's start,
/// not from the rebuild, so the gusts (sin 2π·f·t) blow the same. This is
/// what lets a recorded daemon session replay exactly offline.
#[test]
fn a_cloth_rebuilt_mid_run_continues_bit_for_bit() {
    let scene = Scene::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/scenes/banner-1to3-gusts.toml"
    )))
    .expect("shipped scene loads");
    let mut whole = scene.build_at(9, 5).expect("builds");
    let mut rebuilt = whole.clone();
    for _ in 0..777 {
        whole.step();
        rebuilt.step();
    }
    for rebuild in 0..3 {
        let state = rebuilt.state().clone();
        rebuilt = scene.build_at(9, 5).expect("builds");
        rebuilt.set_state(state).expect("same size");
        for _ in 0..1111 {
            whole.step();
            rebuilt.step();
        }
        assert!(
            bits(whole.state()) == bits(rebuilt.state()),
            "rebuild {rebuild}: t {:?} vs {:?}",
            whole.state().time,
            rebuilt.state().time
        );
    }
}
