//! What enters the engine: commands, applied between steps.

use std::sync::Arc;

use tokio::sync::oneshot;

use super::{ControlOutcome, RestoreError, Snapshot, SwitchError, SwitchOutcome};
use crate::plan::{Level, Prepared};
use crate::points::cloud::CloudMap;
use crate::sim::Simulation;
use crate::touch::{Input, TouchError};

use super::InputOutcome;

/// Commands, applied between steps.
pub enum Command {
    /// Continue at `level` from the current state (transferred). `sim` is
    /// the new level at rest, built off the stepping thread: with
    /// `prepared`'s coefficients, or for an at-once switch (`prepared`
    /// `None`) with the scene's own (method `same`; no prediction and no
    /// shadow reference until the estimate follows as a same-level switch).
    Switch {
        level: Level,
        prepared: Option<Arc<Prepared>>,
        sim: Box<Simulation>,
        /// Surfaces: the new level's cloud map (built off the stepping thread too).
        cloud: Option<Box<CloudMap>>,
        /// A switch down with `switch_settle`: the new level's settling
        /// twin (`lod::settler`, built off the stepping thread too; made
        /// there when missing).
        settler: Option<Box<Simulation>>,
        reply: oneshot::Sender<Result<SwitchOutcome, SwitchError>>,
    },
    Pause {
        paused: bool,
        reply: oneshot::Sender<ControlOutcome>,
    },
    /// Start the scene over from rest at the current level.
    Reset { reply: oneshot::Sender<ControlOutcome> },
    /// A client's input, applied between two steps (see [`crate::touch`]);
    /// refused for a surface or when the input does not fit the cloth.
    Input {
        input: Input,
        reply: oneshot::Sender<Result<InputOutcome, TouchError>>,
    },
    /// A copy of the instance's state; `None` while it is held or halted
    /// (nothing worth resuming).
    Snapshot {
        reply: oneshot::Sender<Option<Box<Snapshot>>>,
    },
    /// Release an instance started with [`InstanceSetup::hold`]: resume
    /// `saved` (at `prepared`'s level and coefficients when given; with
    /// `sim` alone, at the snapshot's own coefficients, `sim` built with
    /// them, and no prediction or shadow until an [`Command::Attach`]; with
    /// neither, at the current ones), or with `saved` `None` start from
    /// rest. On error the instance starts from rest too.
    Restore {
        prepared: Option<Arc<Prepared>>,
        sim: Option<Box<Simulation>>,
        cloud: Option<Box<CloudMap>>,
        saved: Option<Box<Snapshot>>,
        reply: oneshot::Sender<Result<(), RestoreError>>,
    },
    /// Give an instance resumed from its snapshot's coefficients its
    /// prepared level (predicted error, error normaliser, shadow reference),
    /// if it still runs exactly what was prepared: the same level, method,
    /// coefficient version, material and dt. Replies whether it did.
    Attach {
        prepared: Arc<Prepared>,
        coefficient_version: u32,
        reply: oneshot::Sender<bool>,
    },
}
