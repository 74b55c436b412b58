//! Why the engine refused a command: what crosses back to the service in a
//! command's reply, one variant per way it can fail.

use crate::lod::LodError;
use crate::plan::Level;
use crate::sim::SimError;
use crate::touch::TouchError;

/// Why a [`super::Command::Switch`] was refused: the instance runs on at
/// its level as if it had not been asked.
#[derive(Debug, thiserror::Error)]
pub enum SwitchError {
    /// The prepared level is not the one the switch names.
    #[error("prepared for {prepared}, asked for {asked}")]
    PreparedForAnother {
        /// The level the coefficients were prepared for.
        prepared: Level,
        /// The level the switch names.
        asked: Level,
    },
    /// A cloth cannot become a surface, nor a surface a cloth.
    #[error("a switch between a cloth and a surface level")]
    KindChange,
    /// The cloth's state could not be carried onto the new level's nodes.
    #[error(transparent)]
    Transfer(LodError),
    /// The new level refused the carried state.
    #[error(transparent)]
    State(SimError),
    /// Settling the carried shape on the coarser level failed.
    #[error(transparent)]
    Settle(SimError),
}

/// Why a [`super::Command::Restore`] did not resume its snapshot: the
/// instance starts from rest instead.
#[derive(Debug, thiserror::Error)]
pub enum RestoreError {
    /// Only a held instance resumes a snapshot.
    #[error("the instance is already running")]
    Running,
    /// The snapshot's level is not the level it would resume at.
    #[error("the snapshot is at {saved}, the simulation at {level}")]
    OtherLevel {
        /// The snapshot's level.
        saved: Level,
        /// The level it would resume at.
        level: Level,
    },
    /// A simulation alone comes with the snapshot's coefficients, which
    /// this snapshot does not hold.
    #[error("a restore without a prepared level needs the snapshot's coefficients")]
    NoCoefficients,
    /// The simulation given differs from the snapshot's coefficients.
    #[error("the simulation was not built with the snapshot's coefficients")]
    OtherCoefficients,
    /// A prepared level came without its simulation.
    #[error("a restore needs both the prepared level and its simulation")]
    NoSimulation,
    /// The simulation refused the saved state.
    #[error(transparent)]
    State(SimError),
    /// The inputs in force could not be let go of.
    #[error(transparent)]
    Inputs(TouchError),
}

/// The engine's threads have stopped: a command can no longer be queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the engine has stopped")]
pub struct Stopped;
