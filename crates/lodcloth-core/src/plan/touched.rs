//! A prepared level's prediction under input ([`crate::estimate::touched`]):
//! the reference under each standard drag is recorded once per instance,
//! then each level is scored under every drag; the prediction is the
//! largest of its errors. Blocking (a reference run per drag, then a level
//! run per drag); the daemon runs it in the background after a level is
//! live.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use super::prepare::lock;
use super::{Basis, Level, PrepareError, Prepared, Preparer};
use crate::estimate::{probes, record_touched, Method, TouchedError, TouchedReference, TouchedScore};

/// A level's error under the standard drags.
#[derive(Debug, Clone)]
pub struct TouchedPrediction {
    /// The largest of the drags' eq. 9 errors (normalised by the recorded
    /// reference's largest displacement, like the predicted error).
    pub error: f64,
    /// Each drag's error, in the probes' order.
    pub scores: Vec<TouchedScore>,
    /// Wall time this level's runs took (s), not counting the references.
    pub seconds: f64,
}

/// What a [`Preparer`] keeps of the drags: the references under them (one
/// set per instance: every level shares the recorded reference) and every
/// level's prediction.
#[derive(Debug, Default)]
pub(super) struct TouchedCache {
    references: Mutex<Option<Arc<Vec<TouchedReference>>>>,
    predictions: Mutex<HashMap<(Level, Method), Arc<TouchedPrediction>>>,
}

impl Preparer {
    /// `prepared`'s prediction under input, if it has been made.
    pub fn touched_prediction(&self, level: Level, method: Method) -> Option<Arc<TouchedPrediction>> {
        lock(&self.touched.predictions).get(&(level, method)).cloned()
    }

    /// Make `prepared`'s prediction under input (blocking; kept after the
    /// first time). Cloth levels only: `Ok(None)` for a surface, which
    /// takes no input. `stop` is asked as it goes (then it fails, keeping
    /// nothing half made).
    pub fn predict_touched(
        &self,
        prepared: &Prepared,
        stop: &dyn Fn() -> bool,
    ) -> Result<Option<Arc<TouchedPrediction>>, PrepareError> {
        let Basis::Cloth(problem) = &prepared.basis else {
            return Ok(None);
        };
        let key = (prepared.level, prepared.method);
        if let Some(p) = self.touched_prediction(key.0, key.1) {
            return Ok(Some(p));
        }
        let failed = |e: TouchedError| PrepareError::Failed {
            level: prepared.level,
            method: prepared.method,
            source: Box::new(e.into()),
        };
        let references = {
            let mut slot = lock(&self.touched.references);
            match slot.as_ref() {
                Some(r) => r.clone(),
                None => {
                    let started = Instant::now();
                    let drags = probes(&problem.scene, &problem.reference).map_err(failed)?;
                    let recorded = drags
                        .iter()
                        .map(|p| record_touched(&problem.scene, &problem.reference, p, stop))
                        .collect::<Result<Vec<_>, _>>()
                        .map_err(failed)?;
                    tracing::info!(
                        instance = %self.plan().name,
                        drags = recorded.len(),
                        seconds = started.elapsed().as_secs_f64(),
                        "reference recorded under the standard drags"
                    );
                    let recorded = Arc::new(recorded);
                    *slot = Some(recorded.clone());
                    recorded
                }
            }
        };
        let started = Instant::now();
        let scores = references
            .iter()
            .map(|r| problem.score_touched(prepared.material, r, stop))
            .collect::<Result<Vec<_>, _>>()
            .map_err(failed)?;
        let error = scores.iter().map(|s| s.report.mean).fold(0.0, f64::max);
        let prediction = Arc::new(TouchedPrediction {
            error,
            scores,
            seconds: started.elapsed().as_secs_f64(),
        });
        tracing::info!(
            instance = %self.plan().name,
            level = %prepared.level,
            method = %prepared.method,
            predicted_error = prepared.predicted_error,
            predicted_touched = error,
            seconds = prediction.seconds,
            "level predicted under the standard drags"
        );
        lock(&self.touched.predictions).insert(key, prediction.clone());
        Ok(Some(prediction))
    }
}
