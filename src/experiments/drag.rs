//! Coherence under input (issue 22): one scripted session of touches
//! replayed on the reference and on each level, and each level's eq. 9
//! error under it set against the error it was calibrated to predict on the
//! scene's own script. A level is coherent under input when a user's touch
//! moves it the way it moves the reference, so the prediction a client
//! reads in `Metrics` still holds while it interacts.

use std::sync::Arc;

use crate::estimate::{record_touched, ErrorAccumulator, Method, Probe, TouchedReference};
use crate::plan::{Basis, Level, Preparer};
use crate::touch::{Script, Touch};

/// One level under the script.
#[derive(Debug, Clone, PartialEq)]
pub struct DragCoherence {
    pub level: Level,
    pub method: Method,
    /// Calibrated eq. 9 error without input (what `Metrics` predicts).
    pub predicted: f64,
    /// Eq. 9 error under the script, against the reference under the same
    /// script, normalised by that reference's own largest displacement.
    pub dragged: f64,
    /// The level left alone (no input) against the touched reference: how
    /// far the touches take the cloth from its script, in the same units.
    pub untouched: f64,
    /// The touched reference's largest displacement from rest (m), the
    /// normaliser of `dragged` and `untouched`.
    pub touched_o_max: f64,
    /// The recorded (untouched) reference's, the normaliser of `predicted`
    /// and of the daemon's live error (m).
    pub recorded_o_max: f64,
}

/// Run each of `levels` (prepared with `method`) and the reference under
/// `script` over the reference's recorded span, and score them.
pub fn drag_coherence(
    preparer: &Preparer,
    levels: &[Level],
    method: Method,
    script: &Script,
) -> Result<Vec<DragCoherence>, String> {
    let mut reference: Option<(Arc<crate::estimate::Reference>, TouchedReference)> = None;
    let mut out = Vec::new();
    for &level in levels {
        let prepared = preparer.prepare(level, method).map_err(|e| e.to_string())?;
        let Basis::Cloth(problem) = &prepared.basis else {
            return Err(format!("{level}: drags are for cloth levels"));
        };
        if reference
            .as_ref()
            .is_none_or(|(r, _)| !Arc::ptr_eq(r, &problem.reference))
        {
            let r = problem.reference.clone();
            let probe = Probe {
                name: "the script".into(),
                script: script.clone(),
            };
            let touched = record_touched(&problem.scene, &r, &probe, &|| false).map_err(|e| e.to_string())?;
            reference = Some((r, touched));
        }
        let (r, touched) = reference.as_ref().expect("recorded above");
        // Scored against the touched reference, renormalised by its own
        // largest displacement; then the level left alone against it.
        let renormalise = r.o_max / touched.o_max;
        let dragged = problem
            .score_touched(prepared.material, touched, &|| false)
            .map_err(|e| e.to_string())?
            .report
            .mean
            * renormalise;
        let alone = TouchedReference {
            probe: Probe {
                name: "no input".into(),
                script: Script::default(),
            },
            ..touched.clone()
        };
        let untouched = problem
            .score_touched(prepared.material, &alone, &|| false)
            .map_err(|e| e.to_string())?
            .report
            .mean
            * renormalise;
        out.push(DragCoherence {
            level,
            method,
            predicted: prepared.predicted_error,
            dragged,
            untouched,
            touched_o_max: touched.o_max,
            recorded_o_max: r.o_max,
        });
    }
    Ok(out)
}

/// A recorded session (a level's states while clients touched it) scored
/// against the reference replaying the same inputs: the live error the
/// daemon withholds while a cloth is touched, computed afterwards.
#[derive(Debug, Clone)]
pub struct ReplayedError {
    /// (simulated time, mean eq. 9 error of the frame) per recorded frame
    /// scored.
    pub frames: Vec<(f64, f64)>,
    /// Over every scored frame and node.
    pub report: crate::estimate::ErrorReport,
    /// The touched reference's largest displacement from rest (m).
    pub o_max: f64,
}

/// Score `recorded` states of a `level` (time, SoA positions, in time
/// order, from the episode's start) against the scene at `reference`
/// replaying `script` from rest, from the first input on. `progress` sees
/// the fraction done.
pub fn replayed_error(
    scene: &crate::scene::Scene,
    reference: (usize, usize),
    level: (usize, usize),
    recorded: &[(f64, Vec<f64>)],
    script: &Script,
    progress: &mut dyn FnMut(f64),
) -> Result<ReplayedError, String> {
    let first = script.events().first().map_or(0.0, |e| e.0);
    let scored: Vec<&(f64, Vec<f64>)> = recorded.iter().filter(|(t, _)| *t >= first).collect();
    let last = scored.last().ok_or("no recorded state at or after the first input")?.0;
    let mut sim = scene.build_at(reference.0, reference.1).map_err(|e| e.to_string())?;
    let coarse = scene.shape(level.0, level.1);
    let correlation =
        crate::lod::Correlation::grids(&scene.shape(reference.0, reference.1), &coarse).map_err(|e| e.to_string())?;
    let n = level.0 * level.1;
    if let Some((t, p)) = scored.iter().find(|(_, p)| p.len() != 3 * n) {
        return Err(format!(
            "the state at t = {t:.4} s has {} nodes, not the {n} of {}x{}",
            p.len() / 3,
            level.0,
            level.1
        ));
    }
    // The reference under the inputs, mapped onto the level's nodes at
    // each recorded time (nearest step), and its largest displacement.
    let mut touch = Touch::new(scene);
    let mut next = 0;
    let rest = sim.state().pos.clone();
    let nr = sim.topology().n_nodes;
    let dt = sim.params().dt;
    let mut o_max2: f64 = 0.0;
    let mut mapped = Vec::with_capacity(scored.len());
    for (t, _) in &scored {
        while sim.state().time < t - 0.5 * dt {
            script
                .apply_due(&mut next, &mut touch, &mut sim)
                .map_err(|e| format!("the reference refused an input: {e}"))?;
            if !sim.step().finite {
                return Err(format!(
                    "the touched reference diverged at t = {:.4} s",
                    sim.state().time
                ));
            }
            let pos = &sim.state().pos;
            for k in 0..nr {
                o_max2 = o_max2.max(
                    (0..3)
                        .map(|c| (pos[c * nr + k] - rest[c * nr + k]).powi(2))
                        .sum::<f64>(),
                );
            }
        }
        let mut m = vec![0.0; 3 * n];
        correlation.map(&sim.state().pos, &mut m);
        mapped.push(m);
        progress(sim.state().time / last);
    }
    let o_max = o_max2.sqrt();
    if !(o_max > 0.0) {
        return Err("the touched reference did not move".into());
    }
    let mut acc = ErrorAccumulator::new(o_max, n, scored.len());
    let mut frames = Vec::with_capacity(scored.len());
    for ((t, pos), r) in scored.iter().zip(&mapped) {
        let mean = (0..n)
            .map(|k| {
                (0..3)
                    .map(|c| (pos[c * n + k] - r[c * n + k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum::<f64>()
            / n as f64
            / o_max;
        frames.push((*t, mean));
        acc.push(*t, r, pos);
    }
    Ok(ReplayedError {
        frames,
        report: acc.report(),
        o_max,
    })
}
