//! Issue 22, coherence under input: a user's drag replayed on the
//! reference and on each level (`experiments::drag`). Every level follows
//! the drag (its error is a fraction of how far the drag takes the cloth
//! from its script), and the scene's own material converges under it.
//! The issue's target, each level within 1.5× of its predicted error, is
//! asserted for BCD under five drags (0.57–1.16×) and printed for the
//! scene's own material, which misses it (1.1–9.0×): its prediction is
//! calibrated on the scripted motion, and its error under a touch grows
//! with how far the touch folds the cloth (docs/results.md, "Coherence
//! under input"). The daemon publishes the error under input live instead
//! (tests/live_error.rs).

use std::sync::Arc;

use lodcloth::estimate::{eased_drag, Method};
use lodcloth::plan::{Level, Preparer};
use lodcloth::service::config::ServiceConfig;
use lodcloth::touch::{Input, Patch, Script};
use lodcloth_lab::experiments::drag::drag_coherence;

/// Paper scene 1 (top edge pinned, pulled down 1.0–2.5 s) with a 24×24
/// reference over its first 3 s, as the daemon tests run it.
fn preparer() -> Preparer {
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/paper-1-top-edge.toml");
    let text = format!(
        r#"
[estimation]
reference_steps = 15000
metric_stride = 25
estimate_stride = 25
precompute = false
[[instances]]
name = "drag"
scene = "{}"
reference = "24x24"
levels = ["8x8", "12x12", "16x16"]
start = "8x8"
method = "same"
"#,
        scene.display()
    );
    let config = ServiceConfig::from_toml(&text, "drag test").expect("valid config");
    Preparer::new(Arc::new(config.instances[0].clone()), config.estimation, None)
}

/// Where the patch `at` of the reference is at `t0` (no input before).
fn reference_patch_at(preparer: &Preparer, at: Patch, t0: f64) -> [f64; 3] {
    let lodcloth::plan::InstanceKind::Cloth(scene) = &preparer.plan().kind else {
        panic!("a cloth")
    };
    let mut sim = scene.build().expect("builds");
    while sim.state().time < t0 - 0.5 * sim.params().dt {
        sim.step();
    }
    let shape = sim.topology().grid.expect("grid");
    let (nodes, weights) = at.weights(&shape);
    let g = lodcloth::sim::Grab {
        nodes,
        weights,
        target: [0.0; 3],
        stiffness: 0.0,
        damping: 0.0,
    };
    g.patch(&sim.state().pos, &sim.state().vel).0
}

/// A hand closes on the patch where it is at `t0` and carries it along a
/// smooth path (cosine-eased legs, 60 target updates a second), then lets
/// go.
fn smooth_drag(start: [f64; 3], at: Patch, t0: f64, stiffness: f64, legs: &[[f64; 3]]) -> Script {
    let grab = Input::Grab {
        id: 1,
        at,
        target: None,
        stiffness,
        damping: 0.1,
    };
    Script::new(eased_drag(grab, t0, start, legs, 0.6, 0.3, 60.0)).expect("valid")
}

#[test]
fn a_drag_replayed_on_every_level_is_followed_and_the_replay_of_no_input_is_the_calibration() {
    let preparer = preparer();
    let levels = [Level::new(8, 8), Level::new(12, 12), Level::new(16, 16)];
    // The harness itself: replaying an empty script reproduces each
    // level's calibrated error exactly (same frames, same normaliser).
    for r in drag_coherence(&preparer, &levels, Method::Same, &Script::default()).expect("runs") {
        assert!(
            (r.dragged - r.predicted).abs() <= 1e-12 * r.predicted,
            "{}: replayed {} against calibrated {}",
            r.level,
            r.dragged,
            r.predicted
        );
    }
    // A hand closes on a bottom corner as the cloth falls, carries it up
    // and out, then across, and lets go.
    let at = Patch {
        u: 0.75,
        v: 1.0,
        radius: 0.05,
    };
    let t0 = 0.4;
    let start = reference_patch_at(&preparer, at, t0);
    let script = smooth_drag(start, at, t0, 4.0, &[[-0.1, 0.25, 0.35], [0.3, 0.0, -0.2]]);
    for method in [Method::Same, Method::Bcd] {
        let rows = drag_coherence(&preparer, &levels, method, &script).expect("runs");
        for r in &rows {
            eprintln!(
                "{} {}: predicted {:.3} %, under the drag {:.3} % ({:.2}x the prediction), left alone {:.3} %",
                r.level,
                r.method,
                100.0 * r.predicted,
                100.0 * r.dragged,
                r.dragged / r.predicted,
                100.0 * r.untouched
            );
            // Every level follows the drag: its error is a fraction of how
            // far the drag takes the cloth from its script (a level that
            // ignored the input would be at 1).
            assert!(
                r.dragged < 0.5 * r.untouched,
                "{} {}: {:.3} % under the drag, {:.3} % if it ignored it",
                r.level,
                r.method,
                100.0 * r.dragged,
                100.0 * r.untouched
            );
        }
        if method == Method::Same {
            // The scene's own material converges under interaction too.
            assert!(
                rows.windows(2).all(|w| w[1].dragged < w[0].dragged),
                "same: the error under the drag does not fall with resolution"
            );
        }
    }
}

/// Five drags, none tuned: where the hand takes the cloth (material
/// point), when, how stiffly, and where it carries it.
fn five_drags(preparer: &Preparer) -> Vec<(&'static str, Script)> {
    let drag = |u: f64, v: f64, t0: f64, stiffness: f64, legs: &[[f64; 3]]| {
        let at = Patch { u, v, radius: 0.05 };
        smooth_drag(reference_patch_at(preparer, at, t0), at, t0, stiffness, legs)
    };
    vec![
        (
            "bottom centre, up and out, across (6 N/m)",
            drag(0.5, 1.0, 0.3, 6.0, &[[0.0, 0.3, 0.3], [0.3, 0.0, 0.0]]),
        ),
        (
            "bottom corner, up and out, across (4 N/m)",
            drag(0.75, 1.0, 0.4, 4.0, &[[-0.1, 0.25, 0.35], [0.3, 0.0, -0.2]]),
        ),
        (
            "side, in and out, down (10 N/m)",
            drag(0.25, 0.75, 0.8, 10.0, &[[-0.3, 0.0, 0.2], [0.0, -0.2, 0.2]]),
        ),
        (
            "middle, a soft tug sideways (2 N/m)",
            drag(0.5, 0.6, 1.5, 2.0, &[[0.2, 0.2, 0.0]]),
        ),
        (
            "near a corner, out then across (20 N/m)",
            drag(0.9, 0.9, 0.6, 20.0, &[[0.0, 0.0, 0.3], [-0.4, 0.0, 0.0]]),
        ),
    ]
}

/// The issue's target on five drags, with the error normalised like the
/// daemon's live error and its predictions (by the recorded reference's
/// largest displacement). Against the prediction calibrated on the script,
/// BCD's error stays below 1.5× under every drag and the scene's own
/// material's does not under any vigorous one (its error grows with how far
/// the drag folds the cloth). Against the prediction *under input* (the
/// largest error under the scene's three standard drags,
/// `lodcloth_core::estimate::touched`, fixed by rule and sharing nothing
/// with these five), both stay below 1.5× under every drag.
#[test]
fn under_five_drags_each_level_stays_within_one_and_a_half_times_its_prediction_under_input() {
    let preparer = preparer();
    let levels = [Level::new(8, 8), Level::new(12, 12), Level::new(16, 16)];
    let drags = five_drags(&preparer);
    for method in [Method::Bcd, Method::Same] {
        let mut touched = Vec::new();
        for &level in &levels {
            let prepared = preparer.prepare(level, method).expect("prepares");
            let t = preparer
                .predict_touched(&prepared, &|| false)
                .expect("predicts under the drags")
                .expect("a cloth");
            let each: Vec<String> = t
                .scores
                .iter()
                .map(|s| format!("{} {:.3} %", s.probe, 100.0 * s.report.mean))
                .collect();
            eprintln!(
                "{method} {level}: predicted {:.3} %, under input {:.3} % ({})",
                100.0 * prepared.predicted_error,
                100.0 * t.error,
                each.join("; ")
            );
            touched.push((level, t.error));
        }
        let mut ratios = Vec::new();
        for (name, script) in &drags {
            let rows = drag_coherence(&preparer, &levels, method, script).expect("runs");
            let cells: Vec<String> = rows
                .iter()
                .map(|r| {
                    // Normalised like the live error and the predictions.
                    let e = r.dragged * r.touched_o_max / r.recorded_o_max;
                    let under_input = touched.iter().find(|t| t.0 == r.level).expect("predicted").1;
                    ratios.push((r.level, *name, e / r.predicted, e / under_input));
                    format!(
                        "{} {:.3} % ({:.2}x, {:.2}x under input)",
                        r.level,
                        100.0 * e,
                        e / r.predicted,
                        e / under_input
                    )
                })
                .collect();
            eprintln!("{method} under '{name}': {}", cells.join(", "));
        }
        let range = |pick: fn(&(Level, &str, f64, f64)) -> f64| {
            ratios
                .iter()
                .map(pick)
                .fold((f64::INFINITY, 0.0f64), |(lo, hi), r| (lo.min(r), hi.max(r)))
        };
        let (lo, hi) = range(|r| r.2);
        let (tlo, thi) = range(|r| r.3);
        eprintln!(
            "{method}: error under a drag / predicted error from {lo:.2}x to {hi:.2}x; \
             / predicted error under input from {tlo:.2}x to {thi:.2}x"
        );
        for (level, name, scripted, under_input) in &ratios {
            // Not above 1.5× (below is a conservative prediction).
            assert!(
                *under_input <= 1.5,
                "{method} {level} under '{name}': {under_input:.2}x its predicted error under input"
            );
            if method == Method::Bcd {
                assert!(
                    *scripted <= 1.5,
                    "bcd {level} under '{name}': {scripted:.2}x its predicted error"
                );
            }
        }
    }
}
