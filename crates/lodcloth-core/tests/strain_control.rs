//! Super-elasticity control under a heavy, sudden load: Provot strain
//! limiting keeps every limited spring within max_strain·(1 + tolerance)
//! after every step; the Bayraktar stiffness adjustment (passive) reduces the
//! overshoot without bounding it; neither does anything to a lightly loaded
//! cloth.
//!
//! Strains are measured directly from node positions, not taken from the
//! step report (which is checked against them).

use crate::common;

use common::{build, fixed_pins, grid, lumped_masses, material, params, scalar_max_strain};
use lodcloth::sim::{
    Integrator, Loads, NodeLoad, Orientation, Profile, Simulation, SpringKind, StabilityCheck, State,
    StiffnessAdjustment, StrainLimit,
};

const N: usize = 8;
const SIZE: f64 = 0.35;

/// An 8×8 vertical cloth hanging from its top edge; from t = 0 a total force
/// `pull` (N) acts straight down on its bottom edge, split evenly.
fn pulled_cloth(
    integrator: Integrator,
    pull: f64,
    strain_limit: Option<StrainLimit>,
    adjustment: Option<StiffnessAdjustment>,
) -> Simulation {
    let topo = grid(N, N, SIZE, SIZE, Orientation::Vertical);
    let masses = lumped_masses(&topo, 0.2);
    let bottom: Vec<u32> = ((N * (N - 1))..N * N).map(|k| k as u32).collect();
    let loads = Loads {
        forces: vec![NodeLoad {
            shares: vec![1.0 / N as f64; N],
            nodes: bottom,
            force: [0.0, -pull, 0.0],
            profile: Profile::Constant,
        }],
        pins: fixed_pins(&topo, &(0..N).collect::<Vec<_>>()),
        ..Loads::default()
    };
    let mut p = params(2e-4, integrator, material((50.0, 0.01), (10.0, 0.002), (2.0, 0.0004)));
    p.gravity = [0.0, -9.81, 0.0];
    p.drag = 1.0;
    p.strain_limit = strain_limit;
    p.stiffness_adjustment = adjustment;
    build(
        topo.clone(),
        masses,
        p,
        loads,
        State::at_rest(&topo),
        StabilityCheck::Enforce,
    )
}

const STRUCTURAL_AND_SHEAR: [bool; 3] = [true, true, false];

/// Largest strain of the structural and shear springs over `steps` steps.
fn peak_strain(sim: &mut Simulation, steps: usize) -> f64 {
    let mut peak = f64::NEG_INFINITY;
    for _ in 0..steps {
        assert!(sim.step().finite);
        peak = peak.max(scalar_max_strain(sim.topology(), sim.state(), STRUCTURAL_AND_SHEAR));
    }
    peak
}

/// A 20 N pull on a cloth whose columns hold ~2.5 N per 100% strain each: far
/// beyond any sensible limit, suddenly applied.
const HEAVY: f64 = 10.0;

#[test]
fn heavy_load_without_control_overstretches_the_cloth() {
    // The premise of the tests below: the load really is heavy.
    let mut sim = pulled_cloth(Integrator::SymplecticEuler, HEAVY, None, None);
    let peak = peak_strain(&mut sim, 3000);
    eprintln!("no control: peak strain {:.1}%", 100.0 * peak);
    assert!(peak > 0.4);
}

#[test]
fn strain_limiting_keeps_every_limited_spring_within_max_strain_after_every_step() {
    for integrator in [Integrator::SymplecticEuler, Integrator::Rk4, Integrator::ImplicitEuler] {
        let limit = StrainLimit {
            max_strain: 0.10,
            tolerance: 1e-3,
            kinds: STRUCTURAL_AND_SHEAR,
            ..StrainLimit::default()
        };
        let mut sim = pulled_cloth(integrator, HEAVY, Some(limit), None);
        let bound = limit.max_strain * (1.0 + limit.tolerance);
        let (mut worst, mut sweeps, mut bend) = (f64::NEG_INFINITY, 0u64, f64::NEG_INFINITY);
        for _ in 0..3000 {
            let r = sim.step();
            assert!(r.finite, "{integrator} diverged at step {}", r.step);
            let s = scalar_max_strain(sim.topology(), sim.state(), STRUCTURAL_AND_SHEAR);
            assert!(
                s <= bound + 1e-12,
                "{integrator}, step {}: strain {s} beyond {bound}",
                r.step
            );
            // The report agrees with the positions.
            let reported = r.max_strain[SpringKind::Structural.index()].max(r.max_strain[SpringKind::Shear.index()]);
            assert!((reported - s).abs() < 1e-12, "report {reported} vs measured {s}");
            worst = worst.max(s);
            bend = bend.max(r.max_strain[SpringKind::Bend.index()]);
            sweeps += u64::from(r.strain_iterations);
        }
        eprintln!(
            "{integrator} + strain limit 10%: peak strain {:.4}% over 3000 steps ({sweeps} Jacobi sweeps); \
             unlimited bend springs peaked at {:.1}%",
            100.0 * worst,
            100.0 * bend
        );
        // The limit was active, not idle.
        assert!(
            worst > 0.99 * limit.max_strain,
            "limit never reached: the test would measure nothing"
        );
        assert!(sweeps > 0);
    }
}

#[test]
fn strain_limiting_never_moves_pins() {
    let limit = StrainLimit {
        max_strain: 0.05,
        ..StrainLimit::default()
    };
    let mut sim = pulled_cloth(Integrator::SymplecticEuler, HEAVY, Some(limit), None);
    common::run(&mut sim, 500);
    for k in 0..N {
        assert_eq!(sim.state().position(k), sim.topology().rest_positions[k]);
        assert_eq!(sim.state().velocity(k), [0.0; 3]);
    }
}

#[test]
fn stiffness_adjustment_reduces_the_overshoot_beyond_the_allowed_strain() {
    let allowed = 0.10;
    let steps = 3000;
    let free = peak_strain(&mut pulled_cloth(Integrator::SymplecticEuler, HEAVY, None, None), steps);
    let adjusted = peak_strain(
        &mut pulled_cloth(
            Integrator::SymplecticEuler,
            HEAVY,
            None,
            Some(StiffnessAdjustment { allowed }),
        ),
        steps,
    );
    let (over_free, over_adjusted) = (free - allowed, adjusted - allowed);
    eprintln!(
        "sudden {HEAVY} N pull, allowed strain {:.0}%: peak strain {:.1}% without control, {:.1}% with the stiffness \
         adjustment; overshoot {:.1} -> {:.1} points ({:.0}% less)",
        100.0 * allowed,
        100.0 * free,
        100.0 * adjusted,
        100.0 * over_free,
        100.0 * over_adjusted,
        100.0 * (1.0 - over_adjusted / over_free)
    );
    assert!(over_adjusted < over_free, "overshoot not reduced");
    // Passive, as its documentation says: it does not hold the allowed strain.
    assert!(over_adjusted > 0.0);
}

#[test]
fn strain_control_leaves_a_lightly_loaded_cloth_untouched() {
    // A 0.05 N pull stretches nothing near 10%: both controls must be no-ops,
    // bit for bit.
    let light = 0.05;
    let steps = 1500;
    let mut plain = pulled_cloth(Integrator::SymplecticEuler, light, None, None);
    let peak = peak_strain(&mut plain, steps);
    assert!(peak < 0.05, "the light load is not light: {peak}");
    for (limit, adjustment) in [
        (
            Some(StrainLimit {
                max_strain: 0.10,
                ..StrainLimit::default()
            }),
            None,
        ),
        (None, Some(StiffnessAdjustment { allowed: 0.10 })),
    ] {
        let mut controlled = pulled_cloth(Integrator::SymplecticEuler, light, limit, adjustment);
        common::run(&mut controlled, steps);
        assert!(
            controlled.state() == plain.state(),
            "{limit:?} {adjustment:?} changed a lightly loaded run"
        );
    }
}
