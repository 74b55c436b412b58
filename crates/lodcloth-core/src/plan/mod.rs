//! Planning levels: what an instance is ([`InstancePlan`]), the levels it
//! runs ([`Level`]), and how a level is made ready to step — the reference
//! recording, a stable dt, coefficients estimated through the on-disk cache,
//! and the level's predicted error ([`Preparer`]). The daemon's engine and
//! the experiments both plan through here, so a level runs the same way in
//! both.

mod estimator;
mod instance;
mod prepare;
mod touched;

pub use crate::level::{GridLevel, Level};
pub use estimator::{
    default_problem, frame_dt, level_dt, notes, progress_every, record_reference, stable_problem, Estimated, Estimator,
    PlanError,
};
pub use instance::{EstimationPlan, InstanceKind, InstancePlan};
pub use prepare::{allowed, Basis, PrepareError, PrepareFailure, Prepared, Preparer, Start};
pub use touched::TouchedPrediction;
