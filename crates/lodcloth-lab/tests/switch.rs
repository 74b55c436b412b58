//! A mid-run switch reference ↔ level (`experiments::lod::switch_test`):
//! positions and energy carried across, better than zeroed velocities, and
//! a switch to the same level that changes nothing.

use std::sync::Arc;

use lodcloth::estimate::{LodProblem, RecordSpec, Reference};
use lodcloth::scene::{MassConvention, Scene};
use lodcloth::sim::Integrator;
use lodcloth_lab::experiments::lod::switch_test;

/// A 20² cloth pinned at the top, its bottom edge pulled for 0.3 s.
fn scene() -> Scene {
    let text = r#"
name = "switch"
[cloth]
width = 1.0
height = 1.0
nx = 20
ny = 20
orientation = "horizontal"
areal_density = 0.2
[springs]
structural = { k = 400.0, c = 0.04 }
shear = { k = 60.0, c = 0.006 }
bend = { k = 8.0, c = 0.0008 }
[simulation]
integrator = "symplectic_euler"
dt = 2e-4
duration = 1.0
drag = 0.2
[[pins]]
nodes = { edge = "top" }
[[forces]]
nodes = { edge = "bottom" }
total = [0.5, -1.0, 0.0]
profile = { kind = "pulse", start = 0.2, duration = 0.3 }
"#;
    Scene::from_toml(text, "switch").unwrap()
}

/// Record `frames` steps of `s` and set up its `level`×`level` problem.
fn problem(s: &Scene, frames: u64, level: usize, dt: f64) -> (Arc<Reference>, LodProblem) {
    let spec = RecordSpec {
        frames,
        metric_stride: 10,
        estimate_stride: 20,
        difference_span: 1,
    };
    let reference = Arc::new(Reference::record(s.build().unwrap(), spec, &mut |_, _| {}).unwrap());
    let p = LodProblem::new(
        s,
        reference.clone(),
        level,
        level,
        MassConvention::Lumped,
        Integrator::SymplecticEuler,
        dt,
    )
    .unwrap();
    (reference, p)
}

#[test]
fn a_mid_run_switch_keeps_positions_and_energy_and_beats_zeroed_velocities() {
    let s = scene();
    let (reference, p) = problem(&s, 4000, 12, 4e-4);
    // Switch in the middle of the pull (t = 0.35 s), score the next 0.2 s.
    let r = switch_test(&p, reference.material, 175, 100).unwrap();
    assert!(r.position_jump < 1e-12, "position jump {}", r.position_jump);
    assert!(r.kinetic_jump < 0.05, "kinetic-energy jump {}", r.kinetic_jump);
    assert!(
        r.error_transfer <= r.error_never_switched,
        "after the switch {} vs never switched {}",
        r.error_transfer,
        r.error_never_switched
    );
    assert!(
        r.error_zero_velocity > 5.0 * r.error_transfer,
        "zeroed velocities {} vs transfer {}",
        r.error_zero_velocity,
        r.error_transfer
    );
    eprintln!("{r:?}");
}

#[test]
fn switching_to_the_same_level_changes_nothing() {
    let s = scene();
    let (reference, p) = problem(&s, 3000, 20, 2e-4);
    let r = switch_test(&p, reference.material, 150, 100).unwrap();
    assert_eq!(r.position_jump, 0.0);
    // Only the f32 rounding of the recorded reference frames remains (~1e-8 of O_max).
    assert!(r.error_transfer < 1e-6 && r.back_error < 1e-6, "{r:?}");
}
