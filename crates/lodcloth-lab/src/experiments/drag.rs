//! Coherence under input (issue 22): one scripted session of touches
//! replayed on the reference and on each level, and each level's eq. 9
//! error under it set against the error it was calibrated to predict on the
//! scene's own script. A level is coherent under input when a user's touch
//! moves it the way it moves the reference, so the prediction a client
//! reads in `Metrics` still holds while it interacts.

use std::sync::Arc;

use lodcloth_core::estimate::{record_touched, Method, Probe, TouchedReference};
use lodcloth_core::plan::{Basis, Level, Preparer};
use lodcloth_core::touch::Script;

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
    let mut reference: Option<(Arc<lodcloth_core::estimate::Reference>, TouchedReference)> = None;
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
