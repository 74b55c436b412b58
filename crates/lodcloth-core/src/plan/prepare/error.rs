//! Why a level could not be prepared, and what failed underneath.

use super::super::estimator::PlanError;
use super::Level;
use crate::estimate::{EstimateError, Method, ReferenceError, TouchedError};
use crate::points::estimate::SurfaceEstimateError;
use crate::points::model::ModelError;
use crate::scene::SceneError;
use crate::sim::{Material, SimError};

/// Why a level could not be prepared.
#[derive(Debug, thiserror::Error)]
pub enum PrepareError {
    /// The level is not one the instance may run.
    #[error("level {level} is not one of the allowed levels {allowed}")]
    NotAllowed {
        /// The level asked for.
        level: Level,
        /// The allowed levels, as [`allowed`] writes them.
        allowed: String,
    },
    /// The level's coefficients are predicted unstable at the dt it must run.
    #[error(
        "level {level} with {method} coefficients is unstable at dt = {dt:e} s (predicted limit {limit:e} s); \
         choose another level or method, or lower the instance's dt"
    )]
    Unstable {
        /// The level asked for.
        level: Level,
        /// The method whose coefficients are unstable.
        method: Method,
        /// The time step it would run at (s).
        dt: f64,
        /// The predicted stability limit (s).
        limit: f64,
    },
    /// Estimation or building the level failed.
    #[error("preparing level {level} with {method}: {source}")]
    Failed {
        /// The level asked for.
        level: Level,
        /// The method asked for.
        method: Method,
        /// What failed (boxed: the underlying errors are large, and this
        /// is the error of every preparation step).
        source: Box<PrepareFailure>,
    },
    /// The instance's reference run could not be recorded.
    #[error("recording the reference of {scene}: {source}")]
    Reference {
        /// The scene's name.
        scene: String,
        /// What failed.
        source: Box<PrepareFailure>,
    },
}

/// What failed underneath a [`PrepareError`]: the error of the step that
/// failed, worded as that step words it.
#[derive(Debug, thiserror::Error)]
pub enum PrepareFailure {
    /// Recording, building, estimating or scoring a cloth level.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The cloth scene could not be built at the level.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A simulation refused its parameters or state.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A cloth level's simulation could not be built.
    #[error(transparent)]
    Estimate(#[from] EstimateError),
    /// A surface's reference run could not be recorded as a cloth
    /// reference (its estimation samples).
    #[error(transparent)]
    Reference(#[from] ReferenceError),
    /// A surface's model could not be built.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// Recording, fitting or scoring a surface level.
    #[error(transparent)]
    Surface(#[from] SurfaceEstimateError),
    /// The prediction under input.
    #[error("under the standard drags: {0}")]
    Touched(#[from] TouchedError),
    /// A method that fits a cloth's coefficients, asked of a surface.
    #[error("`{0}` fits a cloth level's coefficients; a point-sampled surface's are fitted by `fit`")]
    ClothOnly(Method),
    /// An inverse fit gave springs no simulation can run.
    #[error("the estimate is not usable: {0:?}")]
    Unusable(Material),
}
