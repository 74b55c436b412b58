//! Spring forces in f32 (`SpringPrecision::F32`, issue 21's live path):
//! the same bits on every vector path, and a level that moves within its
//! own error of what it does in f64. (The kernel alone against the scalar
//! model is in `kernel::the_f32_kernel_equals_scalar_sung_eq1_to_f32_rounding`;
//! one thread or two in `two_threads`.)

use lodcloth::estimate::{no_progress, RecordSpec};
use lodcloth::plan::{default_problem, record_reference, Level};
use lodcloth::scene::Scene;
use lodcloth::sim::{force_path, Integrator, Profile, Simulation, SpringPrecision, StabilityCheck, VectorPath, Wind};

const FLAG: &str = include_str!("../../../config/scenes/flag-2to1-wind.toml");
const CURTAIN: &str = include_str!("../../../config/scenes/curtain-shaken.toml");
const HANGING: &str = include_str!("../../../config/scenes/hanging.toml");

fn bits(sim: &Simulation) -> Vec<u64> {
    let s = sim.state();
    s.pos.iter().chain(&s.vel).map(|x| x.to_bits()).collect()
}

/// 100 steps of `build()`'s cloth with f32 springs give the same bits on
/// the CPU's best path, on AVX2 and on the baseline, and not the bits of
/// f64 springs.
fn same_bits_on_every_path(label: &str, build: impl Fn() -> Simulation) {
    let run = |precision, path| {
        let before = force_path(path);
        let mut sim = build();
        sim.set_spring_precision(precision);
        assert_eq!(sim.spring_precision(), precision);
        for _ in 0..100 {
            assert!(sim.step().finite, "{label} diverged on {path:?}");
        }
        force_path(before);
        bits(&sim)
    };
    let best = run(SpringPrecision::F32, VectorPath::Best);
    for path in [VectorPath::Avx2, VectorPath::Baseline] {
        assert!(
            run(SpringPrecision::F32, path) == best,
            "{label}: f32 springs on {path:?} differ from the best path"
        );
    }
    assert!(
        run(SpringPrecision::F64, VectorPath::Best) != best,
        "{label}: f32 springs gave f64's bits (the setting did nothing)"
    );
}

/// Every explicit integrator on the windy, strain-limited flag and the
/// shaken curtain (moving pins): 100 steps with f32 springs give the same
/// bits on the CPU's best path, on AVX2 and on the baseline (SSE2 on
/// x86-64, software FMA), and not the bits of f64 springs.
#[test]
fn f32_springs_give_the_same_bits_on_every_vector_path() {
    for (text, name) in [(FLAG, "flag-2to1-wind.toml"), (CURTAIN, "curtain-shaken.toml")] {
        let base = Scene::from_toml(text, name).expect("shipped scene");
        for integrator in [Integrator::ExplicitEuler, Integrator::SymplecticEuler, Integrator::Rk4] {
            let mut scene = base.clone();
            scene.params.integrator = integrator;
            scene.stability = StabilityCheck::Force;
            let (nx, ny) = (33, 21);
            let probe = scene.build_at(nx, ny).expect("builds");
            scene.params.dt = 0.3 * probe.dt_limit();
            let label = format!("{name} {integrator}");
            same_bits_on_every_path(&label, || scene.build_at(nx, ny).expect("builds"));
        }
    }
}

/// What f32 springs change in eq. 9 over a whole scene, against a level's
/// own error: the hanging sheet (a 32×32 reference, 1.5 s: fall, swing,
/// strain limiting) at 12×12 and 16×16 with the scene's coefficients. The
/// eq.-9 error with f32 springs is within 2 % of the error with f64 springs,
/// and the f32 run stays within a tenth of that error of the f64 run on
/// average. Measured: 0.0 % and 0.07 % of the error apart, runs 0.0005 and
/// 0.03 of it apart; with the f32 spring forces scaled by 0.99 (a 1 %
/// systematic error) the runs are 0.12 of the error apart and it fails.
#[test]
fn f32_springs_keep_a_level_within_its_error() {
    let mut scene = Scene::from_toml(HANGING, "hanging.toml").expect("shipped scene");
    (scene.nx, scene.ny) = (32, 32);
    let spec = RecordSpec {
        frames: 15_000,
        metric_stride: 40,
        estimate_stride: 40,
        difference_span: 1,
    };
    let (reference, _) = record_reference(&scene, spec, &mut |_| {}).expect("reference");
    for level in [12, 16] {
        let problem = default_problem(&scene, &reference, (level, level)).expect("level");
        let material = problem.same_material();
        let frames = 0..problem.frames();
        let score = |precision| {
            let r = problem
                .score_in(material, precision, frames.clone(), &mut no_progress)
                .expect("scores");
            assert!(!r.diverged);
            r.mean
        };
        let (e64, e32) = (score(SpringPrecision::F64), score(SpringPrecision::F32));
        // The two runs side by side, at every metric frame.
        let mut a = problem.simulation(material).expect("builds");
        let mut b = a.clone();
        b.set_spring_precision(SpringPrecision::F32);
        let n = a.topology().n_nodes;
        let mut apart = 0.0;
        for &t in &reference.frame_times {
            while a.state().time < t - 0.5 * problem.dt {
                a.step();
                b.step();
            }
            let (pa, pb) = (&a.state().pos, &b.state().pos);
            apart += (0..n)
                .map(|k| ((0..3).map(|c| (pa[c * n + k] - pb[c * n + k]).powi(2)).sum::<f64>()).sqrt())
                .sum::<f64>()
                / n as f64
                / reference.o_max;
        }
        apart /= reference.frame_times.len() as f64;
        eprintln!(
            "hanging {level}x{level}: eq. 9 {:.4} % (f64) {:.4} % (f32), runs {apart:.2e} apart",
            100.0 * e64,
            100.0 * e32
        );
        assert!(e64 > 0.0 && e64 < 0.05, "{level}x{level}: level error {e64}");
        assert!(
            (e32 - e64).abs() < 0.02 * e64,
            "{level}x{level}: f32 springs moved eq. 9 from {e64} to {e32}"
        );
        assert!(apart > 0.0, "the f32 run is the f64 run: the setting did nothing");
        assert!(
            apart < 0.1 * e64,
            "{level}x{level}: runs {apart} apart, level error {e64}"
        );
    }
}

/// Symplectic Euler and RK4 update x and v, write the f32 copies the next
/// force evaluation reads and sum the report in one pass (`sim/nodes.rs`;
/// RK4's stage passes write their stages' copies too). Here against their
/// definition, step by step over 150–2,000 steps of three scenes (the windy
/// flag: f64 forces beside f32 springs; the shaken curtain: moving pins;
/// the hanging sheet with its strain limiter: the pass's results discarded
/// whenever the limiter moves a node), in both precisions:
/// - every free node is, to the bit, where the integrator's formula puts it
///   from accelerations taken afresh: symplectic Euler's v + dt·a and
///   x + dt·v' from the acceleration before the step; RK4's weighted sum of
///   four stages, each stage's acceleration from a copy of the cloth set to
///   that stage's state (its pins where their paths are then), so each
///   stage's f32 copies are those a fresh rounding makes;
/// - the report's kinetic and gravity energies are the sums over free
///   nodes of the new state;
/// - the acceleration after the step is, to the bit, what the same state
///   gives when set afresh (the copies of the new state, pins included).
#[test]
fn a_fused_step_is_its_definition_to_the_bit() {
    for (text, name) in [
        (FLAG, "flag-2to1-wind.toml"),
        (CURTAIN, "curtain-shaken.toml"),
        (HANGING, "hanging.toml"),
    ] {
        // 128×64 (8,192 nodes): the step splits in two halves, whose flat
        // passes cut the x, y, z fields inside a component.
        let sizes: &[(usize, usize)] = if name == "hanging.toml" {
            &[(24, 20)]
        } else {
            &[(24, 20), (128, 64)]
        };
        for (integrator, &(nx, ny)) in [Integrator::SymplecticEuler, Integrator::Rk4]
            .into_iter()
            .flat_map(|i| sizes.iter().map(move |s| (i, s)))
        {
            let mut scene = Scene::from_toml(text, name).expect("shipped scene");
            scene.params.integrator = integrator;
            scene.stability = StabilityCheck::Force;
            scene.params.dt = 0.5 * scene.build_at(nx, ny).expect("builds").dt_limit();
            let dt = scene.params.dt;
            for precision in SpringPrecision::ALL {
                let mut sim = scene.build_at(nx, ny).expect("builds");
                assert_eq!(sim.split().is_some(), nx * ny >= 8192, "{name} {nx}x{ny}: split");
                sim.set_spring_precision(precision);
                let n = sim.topology().n_nodes;
                let masses = sim.masses().to_vec();
                let pinned: Vec<bool> = {
                    let mut p = vec![false; n];
                    for pin in &sim.loads().pins {
                        p[pin.node as usize] = true;
                    }
                    p
                };
                let g = sim.params().gravity;
                let mut limited = 0;
                // The hanging sheet's limiter acts once it has fallen.
                let steps = if name == "hanging.toml" { 2000 } else { 150 };
                for step in 0..steps {
                    let acc = sim.accelerations().to_vec();
                    let (x0, v0) = (sim.state().pos.clone(), sim.state().vel.clone());
                    let expected = match integrator {
                        Integrator::Rk4 => rk4_by_hand(&sim, &acc),
                        _ => {
                            let v: Vec<f64> = (0..3 * n).map(|i| v0[i] + dt * acc[i]).collect();
                            let x = (0..3 * n).map(|i| x0[i] + dt * v[i]).collect();
                            (x, v)
                        }
                    };
                    let report = sim.step();
                    assert!(report.finite, "{name} {integrator} {precision:?}: diverged");
                    limited += usize::from(report.strain_iterations > 0);
                    let s = sim.state();
                    let (mut ke, mut pe) = (0.0, 0.0);
                    for k in (0..n).filter(|&k| !pinned[k]) {
                        let mut v2 = 0.0;
                        for c in 0..3 {
                            let i = c * n + k;
                            if report.strain_iterations == 0 {
                                assert_eq!(
                                    (s.vel[i].to_bits(), s.pos[i].to_bits()),
                                    (expected.1[i].to_bits(), expected.0[i].to_bits()),
                                    "{name} {integrator} {precision:?} step {step}: node {k} component {c}"
                                );
                            }
                            v2 += s.vel[i] * s.vel[i];
                            pe -= masses[k] * g[c] * s.pos[i];
                        }
                        ke += 0.5 * masses[k] * v2;
                    }
                    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (a.abs() + b.abs()) + 1e-15;
                    assert!(
                        close(report.kinetic_energy, ke) && close(report.gravity_energy, pe),
                        "{name} {precision:?} step {step}: report ({}, {}) against sums ({ke}, {pe})",
                        report.kinetic_energy,
                        report.gravity_energy
                    );
                    let after: Vec<u64> = sim.accelerations().iter().map(|a| a.to_bits()).collect();
                    let mut fresh = sim.clone();
                    fresh.set_state(sim.state().clone()).expect("same cloth");
                    let again: Vec<u64> = fresh.accelerations().iter().map(|a| a.to_bits()).collect();
                    assert!(
                        after == again,
                        "{name} {precision:?} step {step}: the acceleration after the step is not the state's"
                    );
                }
                if name == "hanging.toml" {
                    assert!(limited > 0, "the limiter never acted: its path is not tested");
                }
            }
        }
    }
}

/// With f32 springs and no other force, symplectic Euler's update and
/// RK4's first pass take the kernel's f32 forces of the state's evaluation
/// instead of reading accelerations a separate pass wrote
/// (`Simulation::pending`). A cloth stepped that way gives, step by step,
/// the bits of a copy made to write its accelerations after every step
/// (reading them does); and a state set, a wind changed or a copy taken
/// while the forces wait changes nothing either (set, the waiting forces
/// must be dropped: the kernel adds to them).
#[test]
fn an_update_from_the_f32_forces_is_the_cached_acceleration_to_the_bit() {
    for ((text, name), integrator) in [(HANGING, "hanging.toml"), (CURTAIN, "curtain-shaken.toml")]
        .into_iter()
        .flat_map(|s| [Integrator::SymplecticEuler, Integrator::Rk4].map(|i| (s, i)))
    {
        let mut scene = Scene::from_toml(text, name).expect("shipped scene");
        scene.params.integrator = integrator;
        scene.stability = StabilityCheck::Force;
        // 8,192 nodes: the step splits its nodes in two halves
        // (`SPLIT_MIN_NODES`), each with its half of the forces.
        let (nx, ny) = (128, 64);
        scene.params.dt = 0.5 * scene.build_at(nx, ny).expect("builds").dt_limit();
        let mut deferred = scene.build_at(nx, ny).expect("builds");
        assert!(deferred.split().is_some(), "{name}: not split");
        deferred.set_spring_precision(SpringPrecision::F32);
        let mut flushed = deferred.clone();
        for step in 0..400 {
            let (a, b) = (deferred.step(), flushed.step());
            // Written at once, so `flushed` never has forces waiting when
            // the state, the wind or a copy is made below.
            let _ = flushed.accelerations();
            assert!(a.finite && b.finite, "{name} step {step}: diverged");
            assert!(
                bits(&deferred) == bits(&flushed),
                "{name} {integrator} step {step}: the update from the f32 forces differs"
            );
            assert_eq!(a.elastic_energy.to_bits(), b.elastic_energy.to_bits());
            match step {
                // The same state set again: the cache is made afresh.
                100 => {
                    for sim in [&mut deferred, &mut flushed] {
                        let state = sim.state().clone();
                        sim.set_state(state).expect("same cloth");
                    }
                }
                // A copy taken while the forces wait carries on alike.
                200 => deferred = deferred.clone(),
                // A wind: forces in f64 beside the springs from now on.
                300 => {
                    let wind = Some(Wind {
                        velocity: [2.0, 0.0, 1.0],
                        profile: Profile::Constant,
                        air_density: 1.2,
                        drag_coefficient: 1.0,
                    });
                    deferred.set_wind(wind).expect("a valid wind");
                    flushed.set_wind(wind).expect("a valid wind");
                }
                _ => {}
            }
        }
    }
}

/// A lean step (`Simulation::step_lean`: the kernel sums no spring energy
/// or strain) is a step: every integrator, both spring precisions, on the
/// strain-limited hanging sheet, the shaken curtain (moving pins) and the
/// windy flag, split in two halves (8,192 nodes). A cloth stepped lean on
/// two steps of three gives the bits of one stepped in full, its report
/// the same kinetic and gravity energy and finiteness, and NaN for the
/// spring figures; the full step after a lean one reports the figures of
/// its own state (the full run's to the bit), not stale ones.
#[test]
fn a_lean_step_is_a_full_step_without_its_spring_figures() {
    for (text, name) in [
        (HANGING, "hanging.toml"),
        (CURTAIN, "curtain-shaken.toml"),
        (FLAG, "flag-2to1-wind.toml"),
    ] {
        for integrator in Integrator::ALL {
            let mut scene = Scene::from_toml(text, name).expect("shipped scene");
            scene.params.integrator = integrator;
            scene.stability = StabilityCheck::Force;
            let (nx, ny) = (128, 64);
            let probe = scene.build_at(nx, ny).expect("builds");
            let limit = match probe.dt_limit() {
                l if l.is_finite() => l,
                _ => probe.modal().dt_limit(Integrator::SymplecticEuler),
            };
            scene.params.dt = 0.4 * limit;
            // Implicit Euler solves a system a step: fewer of them.
            let steps = if integrator == Integrator::ImplicitEuler {
                12
            } else {
                60
            };
            for precision in SpringPrecision::ALL {
                let mut full = scene.build_at(nx, ny).expect("builds");
                assert!(full.split().is_some(), "{name}: not split");
                full.set_spring_precision(precision);
                let mut lean = full.clone();
                let what = format!("{name} {integrator} {precision:?}");
                for step in 0..steps {
                    let a = full.step();
                    let b = if step % 3 == 2 { lean.step() } else { lean.step_lean() };
                    assert!(a.finite && b.finite, "{what} step {step}: diverged");
                    assert!(bits(&full) == bits(&lean), "{what} step {step}: the lean state differs");
                    assert_eq!(
                        (a.kinetic_energy.to_bits(), a.gravity_energy.to_bits()),
                        (b.kinetic_energy.to_bits(), b.gravity_energy.to_bits()),
                        "{what} step {step}"
                    );
                    // ≥ 0, not > 0: the hanging sheet's first step is at rest,
                    // where every spring is at its rest length to the bit.
                    assert!(a.elastic_energy.is_finite() && a.elastic_energy >= 0.0, "{what}");
                    if step % 3 == 2 {
                        assert_eq!(
                            (a.elastic_energy.to_bits(), a.max_strain.map(f64::to_bits)),
                            (b.elastic_energy.to_bits(), b.max_strain.map(f64::to_bits)),
                            "{what} step {step}: the full step after lean ones"
                        );
                    } else {
                        assert!(
                            b.elastic_energy.is_nan() && b.max_strain.iter().all(|s| s.is_nan()),
                            "{what} step {step}: a lean step reported spring figures"
                        );
                    }
                }
            }
        }
    }
}

/// The report's `finite` is the state's (`State::is_finite`, an
/// independent pass) after a NaN or an infinity is put into one position or
/// velocity of a free node and of a pinned one, full and lean, for
/// symplectic Euler (whose fused pass sums the report) and RK4.
#[test]
fn a_report_is_finite_exactly_when_the_state_is() {
    for integrator in [Integrator::SymplecticEuler, Integrator::Rk4] {
        let mut scene = Scene::from_toml(HANGING, "hanging.toml").expect("shipped scene");
        scene.params.integrator = integrator;
        let sim = scene.build_at(16, 16).expect("builds");
        let n = sim.topology().n_nodes;
        let pinned = sim.loads().pins[0].node as usize;
        let free = n / 2 + 3;
        assert!(sim.loads().pins.iter().all(|p| p.node as usize != free));
        let mut seen_bad = 0;
        for node in [free, pinned] {
            for (field, c, value) in [
                (0, 2, f64::NAN),
                (1, 0, f64::INFINITY),
                (1, 1, f64::NEG_INFINITY),
                (0, 0, f64::INFINITY),
            ] {
                for lean in [false, true] {
                    let mut s = sim.clone();
                    for _ in 0..5 {
                        s.step();
                    }
                    let mut state = s.state().clone();
                    let f = if field == 0 { &mut state.pos } else { &mut state.vel };
                    f[c * n + node] = value;
                    s.set_state(state).expect("same cloth");
                    let r = if lean { s.step_lean() } else { s.step() };
                    assert_eq!(
                        r.finite,
                        s.state().is_finite(),
                        "{integrator} node {node} field {field} component {c} = {value}, lean {lean}"
                    );
                    seen_bad += usize::from(!r.finite);
                }
            }
        }
        assert!(
            seen_bad > 0,
            "{integrator}: no state went non-finite: the test tests nothing"
        );
    }
}

/// One classic RK4 step of `sim` (whose acceleration is `acc`) by hand:
/// each stage's acceleration from a copy of the cloth set to the stage's
/// state and time. Returns the new (x, v); pinned nodes are not meaningful.
fn rk4_by_hand(sim: &Simulation, acc: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (s0, dt) = (sim.state().clone(), sim.params().dt);
    let len = s0.pos.len();
    let (mut sum_pos, mut sum_vel) = (s0.vel.clone(), acc.to_vec());
    let mut stage = s0.clone();
    for i in 0..len {
        stage.pos[i] = s0.pos[i] + 0.5 * dt * s0.vel[i];
        stage.vel[i] = s0.vel[i] + 0.5 * dt * acc[i];
    }
    for (weight, t_stage, next) in [(2.0, 0.5 * dt, 0.5 * dt), (2.0, 0.5 * dt, dt), (1.0, dt, 0.0)] {
        stage.time = s0.time + t_stage;
        let mut at = sim.clone();
        // Puts the pins where their paths are at the stage's time.
        at.set_state(stage.clone()).expect("same cloth");
        let a = at.accelerations().to_vec();
        let sv = at.state().vel.clone();
        for i in 0..len {
            sum_pos[i] += weight * sv[i];
            sum_vel[i] += weight * a[i];
            stage.pos[i] = s0.pos[i] + next * sv[i];
            stage.vel[i] = s0.vel[i] + next * a[i];
        }
    }
    let h6 = dt / 6.0;
    let x = (0..len).map(|i| s0.pos[i] + h6 * sum_pos[i]).collect();
    let v = (0..len).map(|i| s0.vel[i] + h6 * sum_vel[i]).collect();
    (x, v)
}

/// The mesh fast path: f32 springs, and the bending stencils through their
/// assembled operator (`sim::Assembled`). The Cusick disc's 300-vertex
/// level, 100 symplectic steps from rest: the same bits on the CPU's best
/// path, on AVX2 and on the baseline (the operator's gathers are fused
/// multiply-adds in a fixed order, whatever the vector width), and not the
/// bits of the f64 path (stencils, f64 springs).
#[test]
fn a_mesh_bends_through_its_assembled_operator_with_the_same_bits_on_every_vector_path() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/cusick-drape.toml");
    let mut scene = Scene::load(&path).expect("shipped scene");
    scene.params.integrator = Integrator::SymplecticEuler;
    scene.params.dt = 5e-5;
    let cloth = scene.cloth_level(Level::Vertices(300)).expect("a level");
    assert!(!cloth.topology.bending.is_empty(), "the disc bends through stencils");
    same_bits_on_every_path("the Cusick disc at 300v", || {
        scene.build_on(&cloth, scene.material_on(&cloth)).expect("builds")
    });
}
