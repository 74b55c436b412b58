//! Clients' inputs: applied between steps, kept across level switches,
//! let go of when no client has touched the cloth for a while.

use std::time::{Duration, Instant};

use super::runner::Runner;
use super::{AppliedInput, InputOutcome};
use crate::sim::Simulation;
use crate::touch::{Input, Touch, TouchError};

/// Seconds of simulated time over which moved pins return to their
/// scripts when an instance lets go after being left idle.
const PIN_RETURN_SECONDS: f64 = 1.0;

/// Inputs kept for one episode's replica (at the default rate limit, over
/// half an hour of continuous dragging); beyond, the episode's live error
/// is withheld.
const MAX_EPISODE_INPUTS: usize = 100_000;

/// What the input stage keeps.
pub(super) struct Inputs {
    /// Live input (grid cloths only).
    touch: Option<Touch>,
    /// Clients' inputs applied so far.
    client_inputs: u64,
    /// When the last client's input arrived.
    last_input: Instant,
    /// See [`super::InstanceSetup::input_idle`].
    idle: Duration,
    /// An input acted in this episode: the recorded reference no longer
    /// describes the cloth, so there is no live error until the next one.
    touched_episode: bool,
    /// Inputs that took effect in this episode, (time, input) in order:
    /// what a replica starting late replays.
    episode_inputs: Vec<(f64, Input)>,
    /// Inputs applied since the instance started (clients' and the idle
    /// rule's): the last one's `AppliedInput::seq`.
    applied_seq: u64,
}

impl Inputs {
    /// `touch` (`None`: inputs are refused), nothing applied yet at `now`.
    pub(super) fn new(touch: Option<Touch>, now: Instant, idle: Duration) -> Inputs {
        Inputs {
            touch,
            client_inputs: 0,
            last_input: now,
            idle,
            touched_episode: false,
            episode_inputs: Vec::new(),
            applied_seq: 0,
        }
    }

    /// Clients' inputs applied so far.
    pub(super) fn client_inputs(&self) -> u64 {
        self.client_inputs
    }

    /// An input acted in this episode.
    pub(super) fn touched_episode(&self) -> bool {
        self.touched_episode
    }

    /// True while a client's input acts on the cloth at simulated time `t`.
    pub(super) fn active(&self, t: f64) -> bool {
        self.touch.as_ref().is_some_and(|touch| touch.active(t))
    }

    /// Let go of every input on `sim` (a restart, a restore).
    pub(super) fn reset(&mut self, sim: &mut Simulation) -> Result<(), TouchError> {
        match self.touch.as_mut() {
            Some(touch) => touch.reset(sim),
            None => Ok(()),
        }
    }

    /// A new episode: no inputs yet.
    fn new_episode(&mut self) {
        self.touched_episode = false;
        self.episode_inputs.clear();
    }

    /// Keep an input that took effect at `t` for the episode's replica;
    /// false when the episode already has as many as are kept.
    fn keep(&mut self, t: f64, input: Input) -> bool {
        if self.episode_inputs.len() < MAX_EPISODE_INPUTS {
            self.episode_inputs.push((t, input));
            true
        } else {
            false
        }
    }
}

impl Runner {
    /// Apply `input` now, between two steps.
    pub(super) fn input(&mut self, input: &Input) -> Result<InputOutcome, TouchError> {
        let Some(touch) = self.inputs.touch.as_mut() else {
            return Err(TouchError::Field {
                field: "instance",
                value: f64::NAN,
                reason: "live input acts on grid cloths; this instance is a point-sampled surface".into(),
            });
        };
        if self.divergence.halted().is_some() {
            return Err(TouchError::Field {
                field: "instance",
                value: f64::NAN,
                reason: "the instance is halted (it kept diverging); resume or reset it first".into(),
            });
        }
        touch.apply(input, &mut self.sim)?;
        let grabs = touch.grab_ids();
        self.log_input(*input, false);
        self.inputs.client_inputs += 1;
        self.inputs.last_input = Instant::now();
        if !self.inputs.touched_episode {
            // The recorded reference no longer describes the cloth: the
            // live error now comes from a replica replaying the inputs.
            self.inputs.touched_episode = true;
            self.live.clear();
            self.sync_replica();
        }
        Ok(InputOutcome {
            frame: self.frames,
            time: self.sim.state().time,
            grabs,
            level: self.level,
        })
    }

    /// True while a client's input acts on the cloth.
    pub(super) fn touched(&self) -> bool {
        self.inputs.active(self.sim.state().time)
    }

    /// Let go of everything when no input came for the idle time.
    pub(super) fn let_go_if_idle(&mut self, now: Instant) {
        if now.saturating_duration_since(self.inputs.last_input) < self.inputs.idle || !self.touched() {
            return;
        }
        let Some(touch) = self.inputs.touch.as_mut() else {
            return;
        };
        // Once: from here the touch is inactive (or only pins returning).
        self.inputs.last_input = now;
        let letting_go = touch.letting_go(self.sim.state().time, PIN_RETURN_SECONDS);
        for input in letting_go {
            let Some(touch) = self.inputs.touch.as_mut() else {
                return;
            };
            if let Err(e) = touch.apply(&input, &mut self.sim) {
                tracing::error!(instance = %self.name, "letting go failed: {e}");
                return;
            }
            self.log_input(input, true);
        }
        tracing::info!(
            instance = %self.name,
            idle_s = self.inputs.idle.as_secs_f64(),
            "no input for the idle time: grabs released, back to the scene's script"
        );
    }

    /// Hand an input that took effect to the service (which publishes it),
    /// keep it for the episode and pass it to its replica.
    fn log_input(&mut self, input: Input, idle: bool) {
        let t = self.sim.state().time;
        if self.inputs.keep(t, input) {
            self.live.replay_input(t, input);
        } else if self.live.too_many_inputs() {
            tracing::warn!(
                instance = %self.name,
                inputs = MAX_EPISODE_INPUTS,
                "too many inputs in one episode to replay: no live error until the next"
            );
        }
        self.inputs.applied_seq += 1;
        self.publishing.applied(AppliedInput {
            seq: self.inputs.applied_seq,
            frame: self.frames,
            time: self.sim.state().time,
            episode: self.episode,
            level: self.level,
            input,
            idle,
        });
    }

    /// Put the inputs in force on the simulation of a new level.
    pub(super) fn carry_inputs(&mut self) {
        let Some(touch) = self.inputs.touch.as_mut() else {
            return;
        };
        match touch.resolve(&mut self.sim) {
            Ok(softened) => {
                for s in softened {
                    tracing::warn!(
                        instance = %self.name,
                        grab = s.id,
                        from = s.from,
                        to = s.to,
                        "the grab was too stiff for the new level's step: softened to stay stable"
                    );
                }
            }
            Err(e) => tracing::warn!(instance = %self.name, "an input did not carry over to the new level: {e}"),
        }
    }

    /// Start, restart or stop the touched episode's replica to match the
    /// current reference (see [`super::live::LiveError::sync_replica`]).
    pub(super) fn sync_replica(&mut self) {
        self.live
            .sync_replica(&self.name, self.inputs.touched_episode, &self.inputs.episode_inputs);
    }

    /// A new episode (a restart, a restore): no inputs, no replica.
    pub(super) fn forget_episode_inputs(&mut self) {
        self.inputs.new_episode();
        self.live.new_episode();
    }
}
