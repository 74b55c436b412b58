//! The generalisation suite and levels of any shape: each scene gets the
//! named level at its own aspect ratio, estimators are scored on held-out
//! frames in both horizons, and a correction carried to another scene is the
//! other scenes' estimate/reference ratio (so `same`, which changes
//! nothing, carries over exactly).

use std::sync::Arc;

use lodcloth::estimate::{FitOptions, Method, RecordSpec, Reference};
use lodcloth::plan::{Estimator, GridLevel, Level};
use lodcloth::scene::Scene;
use lodcloth::sim::{SpringClass, SpringKind};
use lodcloth_lab::experiments::generalise::{draw_offset, reference_draw, suite, twin_floor, SuiteOptions};
use lodcloth_lab::experiments::lod::{lod_plan, Horizon};

/// A small cloth of `width × height` at `nx × ny`, top edge pinned, pulled
/// at its bottom edge, with fabric stiffness scaled by `k`.
fn scene(name: &str, width: f64, height: f64, nx: usize, ny: usize, k: f64) -> Scene {
    let text = format!(
        r#"
name = "{name}"
[cloth]
width = {width}
height = {height}
nx = {nx}
ny = {ny}
orientation = "horizontal"
areal_density = 0.2
[springs]
structural = {{ k = {}, c = {} }}
shear = {{ k = {}, c = {} }}
bend = {{ k = {}, c = {} }}
[simulation]
integrator = "symplectic_euler"
dt = 2e-4
duration = 1.0
drag = 0.5
[[pins]]
nodes = {{ edge = "top" }}
[[forces]]
nodes = {{ edge = "bottom" }}
total = [0.3, -0.5, 0.2]
profile = {{ kind = "sine", frequency = 1.5 }}
"#,
        300.0 * k,
        0.03 * k,
        50.0 * k,
        0.005 * k,
        6.0 * k,
        0.0006 * k
    );
    Scene::from_toml(&text, name).expect("valid test scene")
}

fn record(scene: &Scene) -> Arc<Reference> {
    let spec = RecordSpec {
        frames: 2000,
        metric_stride: 10,
        estimate_stride: 20,
        difference_span: 1,
    };
    Arc::new(Reference::record(scene.build().expect("builds"), spec, &mut |_, _| {}).expect("records"))
}

fn no_cache() -> Estimator {
    Estimator {
        cache: None,
        tag: "test".into(),
    }
}

#[test]
fn the_suite_scores_each_scene_at_its_aspect_and_carries_corrections_as_ratios() {
    let scenes: Vec<(Scene, Arc<Reference>)> = [
        scene("wide-cotton", 2.0, 1.0, 17, 9, 1.0),
        scene("square-canvas", 1.0, 1.0, 12, 12, 4.0),
    ]
    .into_iter()
    .map(|s| {
        let r = record(&s);
        (s, r)
    })
    .collect();
    let options = SuiteOptions {
        level: GridLevel::Long(9),
        methods: vec![Method::Same, Method::Fit],
        fit: FitOptions {
            max_frames: 20,
            max_iterations: 3,
            ..FitOptions::default()
        },
        train_fraction: 0.5,
        short_window: 0.05,
        floor_perturbation: 1e-6,
        bend_scale: (1.0, 1.0),
        modal: None,
        settle: None,
    };
    let rows = suite(&scenes, &options, &no_cache(), &mut |_| {}).expect("suite runs");
    assert_eq!(rows.len(), 4);
    // The level keeps each cloth's aspect ratio: 9 along the longer side.
    assert_eq!(rows[0].level, Level::new(9, 5));
    assert_eq!(rows[2].level, Level::new(9, 9));
    for r in &rows {
        let t = r.transferred.expect("two scenes: each has the other's correction");
        for v in [
            r.own.mean,
            r.own.p95,
            r.own.last_quarter,
            r.own.short_mean,
            t.mean,
            t.short_mean,
        ] {
            assert!(v.is_finite() && v > 0.0, "{} {}: {v}", r.scene, r.method);
        }
        assert!(r.own.p95 >= r.own.mean, "{} {}: p95 below the mean", r.scene, r.method);
        if r.method == Method::Same {
            // `same` corrects nothing, so the other scene's correction is
            // the identity and the score is the scene's own, exactly.
            assert_eq!(t, r.own, "{}: same carried over", r.scene);
            assert!(r.notes.is_empty(), "{}: same noted {:?}", r.scene, r.notes);
        } else {
            // The fit says where it started and where it stopped (and,
            // when its guard kept the start, why), so a row that scores as
            // `same` can be told from a fit that found `same`.
            assert!(
                r.notes.starts_with("start ") && r.notes.contains("iterations"),
                "{} fit: notes {:?}",
                r.scene,
                r.notes
            );
        }
        assert!(
            r.floor.mean.is_finite() && r.floor.mean < r.own.mean,
            "{}: floor {:?}",
            r.scene,
            r.floor
        );
    }
}

/// The chaos floor's twin is the reference run again: unperturbed it
/// reproduces the recording to its f32 storage (so the floor measures the
/// perturbation and nothing else in the set-up), and on this damped,
/// non-chaotic cloth its error answers a stiffness change linearly.
#[test]
fn the_chaos_floors_twin_reproduces_the_reference_and_answers_its_perturbation() {
    let s = scene("wide-cotton", 2.0, 1.0, 17, 9, 1.0);
    let r = record(&s);
    let frames = r.frames.len();
    let held_out = frames / 2..frames;
    let floor = |eps: f64| twin_floor(&s, &r, held_out.clone(), eps).expect("twin runs");
    let exact = floor(0.0);
    assert!(exact.mean < 1e-6 && exact.p95 < 1e-6, "unperturbed twin: {exact:?}");
    let (small, large) = (floor(1e-4), floor(1e-2));
    assert!(small.mean > 10.0 * exact.mean, "1e-4: {small:?} against {exact:?}");
    let slope = large.mean / small.mean;
    assert!(
        (50.0..200.0).contains(&slope),
        "100× the perturbation gave {slope}× the floor"
    );
}

#[test]
fn lod_plan_takes_levels_of_any_shape_and_skips_those_not_coarser_than_the_reference() {
    let s = scene("wide", 2.0, 1.0, 17, 9, 1.0);
    let reference = record(&s);
    let fit = FitOptions {
        train: Some(0..100),
        max_frames: 20,
        max_iterations: 2,
        ..FitOptions::default()
    };
    let levels = [
        GridLevel::Exact { nx: 17, ny: 9 }, // the reference itself: skipped
        GridLevel::Exact { nx: 20, ny: 5 }, // finer along one side: skipped
        GridLevel::Long(9),                 // 9×5
        GridLevel::Exact { nx: 12, ny: 4 }, // 48 nodes: tried after 9×5 (45)
    ];
    let mut errors = Vec::new();
    for horizon in [Horizon::Long, Horizon::Short { window: 0.05 }] {
        let mut lines = Vec::new();
        let steps = lod_plan(&s, &reference, &levels, 1e9, horizon, &fit, &no_cache(), &mut |l| {
            lines.push(l)
        })
        .expect("plans");
        // The coarsest is tried first, and a bound of 1e9 accepts it at once.
        assert_eq!(steps.len(), 1, "{lines:?}");
        assert_eq!((steps[0].nx, steps[0].ny), (9, 5));
        assert!(steps[0].accepted);
        errors.push(steps[0].held_out_mean);
    }
    // Restarted every 50 ms, the same model drifts less than over the run.
    assert!(errors[1] < errors[0], "short {} vs long {}", errors[1], errors[0]);
}

/// `bend_scale` scores every estimate with its bend class scaled (and
/// only that class), says so in the row's notes, and is refused when it is
/// not a positive factor.
#[test]
fn a_bend_scale_scores_the_estimate_with_its_bend_class_scaled() {
    let s = scene("wide-cotton", 2.0, 1.0, 17, 9, 1.0);
    let scenes = vec![(s.clone(), record(&s))];
    let options = |bend_scale| SuiteOptions {
        level: GridLevel::Long(9),
        methods: vec![Method::Same],
        fit: FitOptions::default(),
        train_fraction: 0.5,
        short_window: 0.05,
        floor_perturbation: 1e-6,
        bend_scale,
        modal: None,
        settle: None,
    };
    let run = |bend_scale| suite(&scenes, &options(bend_scale), &no_cache(), &mut |_| {});
    let plain = run((1.0, 1.0)).expect("runs").remove(0);
    let scaled = run((4.0, 0.5)).expect("runs").remove(0);
    for class in SpringClass::ALL {
        let (a, b) = (
            plain.material.springs[class.index()],
            scaled.material.springs[class.index()],
        );
        let (k, c) = if class.kind() == SpringKind::Bend {
            (4.0, 0.5)
        } else {
            (1.0, 1.0)
        };
        assert!(
            (b.k - k * a.k).abs() <= 1e-12 * a.k.abs().max(1e-300),
            "{class:?}: K {} → {}",
            a.k,
            b.k
        );
        assert!(
            (b.c - c * a.c).abs() <= 1e-12 * a.c.abs().max(1e-300),
            "{class:?}: C {} → {}",
            a.c,
            b.c
        );
    }
    assert!(plain.notes.is_empty(), "{:?}", plain.notes);
    assert!(scaled.notes.contains("bend class K ×4, C ×0.5"), "{:?}", scaled.notes);
    // A four times stiffer bend class moves the level: its score is not
    // `same`'s.
    assert_ne!(scaled.own, plain.own);
    for bad in [(0.0, 1.0), (1.0, -1.0), (f64::NAN, 1.0)] {
        let e = run(bad).expect_err("refused").to_string();
        assert!(e.contains("bend class's scales"), "{bad:?}: {e}");
    }
}

/// A reference draw is the scene with every stiffness — a grid's springs,
/// a mesh's membrane and bending rigidity — × (1 + d·ε), d = 0, +1, −1,
/// +2, −2, and nothing else: damping, masses and shape as written, draw 0
/// the scene itself, every other draw a hash of its own (no cache mixes
/// their estimates). Its recording is another one, a hair away.
#[test]
fn a_reference_draw_scales_every_stiffness_and_nothing_else() {
    assert_eq!([0, 1, 2, 3, 4].map(draw_offset), [0.0, 1.0, -1.0, 2.0, -2.0]);
    let eps = 1e-6;
    let dir = tempfile::tempdir().expect("temp dir");
    let grid = scene("wide-cotton", 2.0, 1.0, 17, 9, 1.0);
    let strip = clamped_strip(dir.path());
    for s in [&grid, &strip] {
        let plain = s.build().expect("builds");
        let mut hashes = vec![s.source_hash];
        for d in 0..5 {
            let drawn = reference_draw(s, d, eps);
            let sim = drawn.build().expect("a draw builds");
            let f = 1.0 + draw_offset(d) * eps;
            let mut stiff = 0;
            for class in SpringClass::ALL {
                let (a, b) = (
                    plain.params().material.springs[class.index()],
                    sim.params().material.springs[class.index()],
                );
                assert!(
                    (b.k - a.k * f).abs() <= 1e-14 * a.k.abs(),
                    "{} draw {d} {class:?}: K {} against {} × {f}",
                    s.name,
                    b.k,
                    a.k
                );
                assert_eq!(b.c, a.c, "{} draw {d} {class:?}: damping changed", s.name);
                stiff += usize::from(a.k > 0.0);
            }
            assert!(stiff >= 3, "{}: {stiff} classes with a stiffness", s.name);
            assert_eq!(sim.state().pos, plain.state().pos, "{} draw {d}: the shape", s.name);
            assert_eq!(
                sim.topology().node_areas,
                plain.topology().node_areas,
                "{} draw {d}: the masses",
                s.name
            );
            if d == 0 {
                assert_eq!(drawn.source_hash, s.source_hash, "draw 0 is the scene");
            } else {
                assert!(
                    !hashes.contains(&drawn.source_hash),
                    "{} draw {d}: a hash of its own",
                    s.name
                );
                hashes.push(drawn.source_hash);
            }
        }
    }
    // Two draws score alike but not the same.
    let run = |d| {
        let s = reference_draw(&grid, d, eps);
        let r = record(&s);
        suite(&[(s, r)], &same_at(GridLevel::Long(9), None), &no_cache(), &mut |_| {})
            .expect("runs")
            .remove(0)
    };
    let (a, b) = (run(0), run(1));
    assert_ne!(a.own.short_mean, b.own.short_mean, "the draw changed nothing");
    assert!(
        (a.own.short_mean - b.own.short_mean).abs() < 1e-3 * a.own.short_mean,
        "a millionth apart, {} against {}",
        a.own.short_mean,
        b.own.short_mean
    );
}

/// A strip clamped at one end, bending under gravity with a bending
/// rigidity (stencils, not bend springs), written into `dir`.
fn clamped_strip(dir: &std::path::Path) -> Scene {
    use lodcloth::mesh::generate;
    let strip = generate::sheet(0.14, 0.03, 0.005);
    let clamp: Vec<usize> = (0..strip.vertices())
        .filter(|&k| strip.positions[k][0] <= 0.02 + 1e-9)
        .collect();
    std::fs::write(dir.join("mesh.obj"), generate::to_obj(&strip, "strip")).expect("mesh");
    let path = dir.join("strip.toml");
    std::fs::write(
        &path,
        format!(
            "name = \"strip\"\n[cloth]\nmesh = \"mesh.obj\"\nareal_density = 0.2\n\
             [material]\nstiffness = {{ stretch_u = 300.0, stretch_v = 300.0, shear = 40.0 }}\n\
             damping_time = 1e-4\nbending_rigidity = 1e-5\n\
             [simulation]\nintegrator = \"implicit_euler\"\ndt = 1e-3\nduration = 2.0\n\
             [[pins]]\nnodes = {{ vertices = {clamp:?} }}\n"
        ),
    )
    .expect("scene");
    Scene::load(&path).expect("a valid mesh scene")
}

/// `same` alone at `level` on the strip, half trained, 0.05 s windows,
/// modes in `modal` stiffened.
fn same_at(level: GridLevel, modal: Option<std::ops::Range<usize>>) -> SuiteOptions {
    SuiteOptions {
        level,
        methods: vec![Method::Same],
        fit: FitOptions::default(),
        train_fraction: 0.5,
        short_window: 0.05,
        floor_perturbation: 1e-6,
        bend_scale: (1.0, 1.0),
        modal,
        settle: None,
    }
}

/// `settle` settles every restart of the short horizon before it runs:
/// the short horizon moves, the long horizon (one run from rest) and the
/// estimate do not, the row's notes say so, and a step that is not a
/// positive time is refused naming it.
#[test]
fn settling_moves_the_short_horizon_alone() {
    let dir = tempfile::tempdir().expect("temp dir");
    let s = clamped_strip(dir.path());
    let scenes = vec![(s.clone(), record(&s))];
    let run = |settle| {
        suite(
            &scenes,
            &SuiteOptions {
                settle,
                ..same_at(GridLevel::Percent(40), None)
            },
            &no_cache(),
            &mut |_| {},
        )
    };
    let plain = run(None).expect("runs").remove(0);
    let settled = run(Some(0.01)).expect("runs").remove(0);
    assert!(plain.notes.is_empty(), "{:?}", plain.notes);
    assert!(
        settled
            .notes
            .contains("restarts settled by a backward-Euler step of 0.01 s"),
        "{:?}",
        settled.notes
    );
    assert_eq!(settled.material, plain.material);
    assert_eq!(
        (settled.own.mean, settled.own.p95),
        (plain.own.mean, plain.own.p95),
        "the long horizon restarts nothing"
    );
    assert_ne!(
        settled.own.short_mean, plain.own.short_mean,
        "the restarts were not settled"
    );
    let e = run(Some(-1.0)).expect_err("refused").to_string();
    assert!(e.contains("settling step"), "{e}");
}

/// `modal` gives every level its bending modes in the band at the
/// reference's stiffness before it is estimated and scored: the level's
/// score moves, the row's notes say so, and a cloth without bending
/// stencils (every grid) is refused naming the scene.
#[test]
fn a_modal_band_scores_the_level_with_its_bending_modes_stiffened() {
    let dir = tempfile::tempdir().expect("temp dir");
    let s = clamped_strip(dir.path());
    let scenes = vec![(s.clone(), record(&s))];
    let options = same_at;
    let run = |modal| {
        suite(
            &scenes,
            &options(GridLevel::Percent(40), modal),
            &no_cache(),
            &mut |_| {},
        )
    };
    let plain = run(None).expect("runs").remove(0);
    let stiffened = run(Some(1..usize::MAX)).expect("runs").remove(0);
    assert!(plain.notes.is_empty(), "{:?}", plain.notes);
    assert!(
        stiffened
            .notes
            .contains("bending modes 1.. stiffened to the reference's"),
        "{:?}",
        stiffened.notes
    );
    assert_eq!(stiffened.material, plain.material, "the coefficients stay `same`'s");
    assert_ne!(stiffened.own, plain.own, "the stiffened stencils were not scored");
    let grid = scene("wide-cotton", 2.0, 1.0, 17, 9, 1.0);
    let grids = vec![(grid.clone(), record(&grid))];
    let e = suite(
        &grids,
        &options(GridLevel::Long(9), Some(0..10)),
        &no_cache(),
        &mut |_| {},
    )
    .expect_err("a grid has no stencils")
    .to_string();
    assert!(e.contains("wide-cotton") && e.contains("no bending stencils"), "{e}");
}
