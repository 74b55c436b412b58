//! One instance on its stepping thread: its state, pacing to the wall
//! clock, and the step itself. Commands, switches, divergence and
//! publishing are the other stages of the same `impl`, one file each.

use std::sync::mpsc::{Receiver, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::watch;

use super::divergence::{CHECKPOINT_INTERVAL, CLEAN_INTERVAL, DIVERGED_STRAIN};
use super::replica::Replica;
use super::shadow::Shadow;
use super::{
    lock, AppliedInput, Command, EngineSettings, HandleParts, InstanceSetup, MetricsFrame, StateFrame, Status,
};
use crate::estimate::Method;
use crate::plan::Level;
use crate::points::cloud::CloudMap;
use crate::sim::{Material, Pair, Simulation, State, StepReport};
use crate::touch::{Input, Touch};

/// One instance on its stepping thread.
pub(super) struct Runner {
    pub(super) name: String,
    pub(super) sim: Simulation,
    pub(super) cloud: Option<CloudMap>,
    pub(super) level: Level,
    pub(super) method: Method,
    pub(super) material: Material,
    pub(super) predicted_error: Option<f64>,
    pub(super) coefficient_version: u32,
    pub(super) shadow: Option<Shadow>,
    pub(super) shadow_wanted: bool,
    pub(super) live_error: Option<f64>,
    /// Simulated time `live_error` is of (behind the cloth's while a
    /// touched episode's replica catches up).
    pub(super) live_error_time: Option<f64>,
    /// A touched episode's reference, replaying its inputs.
    pub(super) replica: Option<Replica>,
    /// The replica of this episode failed (or could not follow a rollback):
    /// no live error until the next episode.
    pub(super) replica_failed: bool,
    /// Inputs that took effect in this episode, (time, input) in order:
    /// what a replica starting late replays.
    pub(super) episode_inputs: Vec<(f64, Input)>,
    /// Inputs applied since the instance started (clients' and the idle
    /// rule's): the last one's `AppliedInput::seq`.
    pub(super) applied_seq: u64,
    /// The reference's largest displacement, once calibrated.
    pub(super) o_max: Option<f64>,
    pub(super) duration: f64,
    pub(super) looping: bool,
    pub(super) commands: Receiver<Command>,
    pub(super) settings: EngineSettings,
    // Pacing: step `steps_since_origin` is due at origin + steps·dt.
    pub(super) origin: Instant,
    pub(super) steps_since_origin: u64,
    pub(super) paused: bool,
    pub(super) frames: u64,
    pub(super) episode: u64,
    pub(super) overruns: u64,
    /// Passes of its thread that woke more than [`super::STALL`] late.
    pub(super) stalls: u64,
    pub(super) lag_resets: u64,
    pub(super) divergences: u64,
    // Divergence recovery: a finite state at most CHECKPOINT_INTERVAL of
    // simulated time old, rolled back to when a step diverges.
    pub(super) checkpoint: State,
    pub(super) rollbacks: u64,
    /// Divergences since the last CLEAN_INTERVAL of clean stepping.
    pub(super) consecutive_divergences: u32,
    pub(super) last_divergence_time: f64,
    pub(super) halted: Option<Arc<str>>,
    /// Waiting for a [`Command::Restore`]: no steps, no states.
    pub(super) held: bool,
    pub(super) last: Option<StepReport>,
    // Metrics window.
    pub(super) window_start: Instant,
    pub(super) window_sim: f64,
    pub(super) window_steps: u64,
    pub(super) window_busy: Duration,
    pub(super) next_publish: Instant,
    pub(super) publish_every: Duration,
    pub(super) next_metrics: Instant,
    pub(super) metrics_every: Duration,
    pub(super) states: watch::Sender<Option<Arc<StateFrame>>>,
    pub(super) metrics: watch::Sender<Option<Arc<MetricsFrame>>>,
    pub(super) transitions: tokio::sync::mpsc::UnboundedSender<Arc<StateFrame>>,
    /// Every input that took effect, for the service to publish.
    pub(super) applied: tokio::sync::mpsc::UnboundedSender<AppliedInput>,
    pub(super) status: Arc<Mutex<Status>>,
    /// Live input (grid cloths only).
    pub(super) touch: Option<Touch>,
    /// Inputs applied so far.
    pub(super) inputs: u64,
    /// When the last input arrived.
    pub(super) last_input: Instant,
    /// See [`InstanceSetup::input_idle`].
    pub(super) input_idle: Duration,
    /// An input acted in this episode: the recorded reference no longer
    /// describes the cloth, so there is no live error until the next one.
    pub(super) touched_episode: bool,
    /// See [`InstanceSetup::switch_settle`].
    pub(super) switch_settle: Option<f64>,
}

impl Runner {
    pub(super) fn new(
        setup: InstanceSetup,
        commands: Receiver<Command>,
        settings: EngineSettings,
    ) -> (Runner, HandleParts) {
        let now = Instant::now();
        let (states_tx, states_rx) = watch::channel(None);
        let (metrics_tx, metrics_rx) = watch::channel(None);
        let (trans_tx, trans_rx) = tokio::sync::mpsc::unbounded_channel();
        let (applied_tx, applied_rx) = tokio::sync::mpsc::unbounded_channel();
        let material = setup.sim.params().material;
        let status = Arc::new(Mutex::new(Status {
            level: setup.level,
            method: setup.method,
            material,
            dt: setup.sim.params().dt,
            coefficient_version: 1,
            predicted_error: None,
            paused: false,
            halted: None,
            topology: setup.sim.topology().clone(),
            pinned: setup.sim.loads().pins.iter().map(|p| p.node).collect(),
            frame: 0,
            o_max: None,
            simulation_points: setup.cloud.as_ref().map(|c| c.kept.clone()),
            cloud_points: setup.cloud.as_ref().map_or(0, |c| c.cloud_points()),
        }));
        let checkpoint = setup.sim.state().clone();
        let runner = Runner {
            name: setup.name.clone(),
            level: setup.level,
            method: setup.method,
            material,
            predicted_error: None,
            coefficient_version: 1,
            shadow: None,
            shadow_wanted: setup.shadow,
            live_error: None,
            live_error_time: None,
            replica: None,
            replica_failed: false,
            episode_inputs: Vec::new(),
            applied_seq: 0,
            o_max: None,
            duration: setup.duration,
            looping: setup.looping,
            sim: setup.sim,
            cloud: setup.cloud,
            commands,
            settings,
            origin: now,
            steps_since_origin: 0,
            paused: false,
            frames: 0,
            episode: 0,
            overruns: 0,
            stalls: 0,
            lag_resets: 0,
            divergences: 0,
            checkpoint,
            rollbacks: 0,
            consecutive_divergences: 0,
            last_divergence_time: f64::NEG_INFINITY,
            halted: None,
            held: setup.hold,
            last: None,
            window_start: now,
            window_sim: 0.0,
            window_steps: 0,
            window_busy: Duration::ZERO,
            next_publish: now,
            publish_every: Duration::from_secs_f64(1.0 / setup.publish_hz),
            next_metrics: now,
            metrics_every: Duration::from_secs_f64(1.0 / settings.metrics_hz),
            states: states_tx,
            metrics: metrics_tx,
            transitions: trans_tx,
            applied: applied_tx,
            status: status.clone(),
            touch: setup.touch,
            inputs: 0,
            last_input: now,
            input_idle: Duration::from_secs_f64(setup.input_idle),
            touched_episode: false,
            switch_settle: setup.switch_settle,
        };
        let parts = HandleParts {
            name: setup.name,
            states: states_rx,
            metrics: metrics_rx,
            transitions: trans_rx,
            applied: applied_rx,
            status,
        };
        (runner, parts)
    }

    pub(super) fn dt(&self) -> f64 {
        self.sim.params().dt
    }

    /// When the next step is due.
    pub(super) fn next_due(&self) -> Instant {
        if self.paused || self.held {
            return self.next_metrics;
        }
        self.origin + Duration::from_secs_f64((self.steps_since_origin + 1) as f64 * self.dt())
    }

    pub(super) fn reanchor(&mut self, now: Instant) {
        self.origin = now;
        self.steps_since_origin = 0;
    }

    /// Apply queued commands.
    pub(super) fn poll_commands(&mut self) {
        loop {
            match self.commands.try_recv() {
                Ok(c) => self.apply(c),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => return,
            }
        }
    }

    pub(super) fn update_status(&self) {
        let mut s = lock(&self.status);
        s.level = self.level;
        s.method = self.method;
        s.material = self.material;
        s.dt = self.dt();
        s.coefficient_version = self.coefficient_version;
        s.predicted_error = self.predicted_error;
        s.paused = self.paused;
        s.halted = self.halted.clone();
        if !Arc::ptr_eq(&s.topology, self.sim.topology()) {
            s.topology = self.sim.topology().clone();
            s.pinned = self.sim.loads().pins.iter().map(|p| p.node).collect();
            s.simulation_points = self.cloud.as_ref().map(|c| c.kept.clone());
        }
        s.frame = self.frames;
        s.o_max = self.o_max;
    }

    /// Take the steps due at `now`.
    pub(super) fn advance(&mut self, now: Instant, pair: &dyn Pair) {
        if self.paused || self.held {
            self.reanchor(now);
            return;
        }
        self.let_go_if_idle(now);
        let dt = self.dt();
        let elapsed = now.saturating_duration_since(self.origin).as_secs_f64();
        let mut due = ((elapsed / dt) as u64).saturating_sub(self.steps_since_origin);
        if due as f64 * dt > self.settings.max_lag {
            self.lag_resets += 1;
            tracing::warn!(instance = %self.name, behind_s = due as f64 * dt, "fell behind real time; dropping the backlog");
            self.reanchor(now);
            due = 1;
        }
        let n = due.min(catch_up_steps(self.settings.max_catch_up, dt));
        if due > n {
            self.overruns += 1;
        }
        if n == 0 {
            return;
        }
        let t0 = Instant::now();
        for k in 0..n {
            self.step_once(pair, k + 1 == n);
            if self.paused {
                break;
            }
        }
        self.window_busy += t0.elapsed();
        self.window_steps += n;
        self.window_sim += n as f64 * dt;
        self.steps_since_origin += n;
    }

    /// One step. `last`: the tick's last, whose report the metrics show. The
    /// others are lean (`Simulation::step_on_lean`: no spring energy or
    /// strain, 9–16 % of a 64×64 step): finiteness is checked every step,
    /// the strain on the tick's last step and before a checkpoint is taken,
    /// so no checkpoint holds a state that was not checked whole.
    pub(super) fn step_once(&mut self, pair: &dyn Pair, last: bool) {
        let checkpoint_due = self.sim.state().time + self.dt() >= self.checkpoint.time + CHECKPOINT_INTERVAL;
        let full = last || checkpoint_due;
        let report = if full {
            self.sim.step_on(pair)
        } else {
            self.sim.step_on_lean(pair)
        };
        self.frames += 1;
        // Non-finite, or finite but absurd (springs at 11× their rest
        // length: positions soon overflow f32 on the wire).
        if !report.finite || (full && report.max_strain_overall() > DIVERGED_STRAIN) {
            self.diverged(report.time);
            return;
        }
        if full {
            self.last = Some(report);
            if report.time >= self.checkpoint.time + CHECKPOINT_INTERVAL {
                // In place: no allocation once the buffers have their size.
                self.checkpoint.clone_from(self.sim.state());
                if report.time >= self.last_divergence_time + CLEAN_INTERVAL {
                    self.consecutive_divergences = 0;
                }
            }
        }
        self.after_step(report.time);
    }

    /// What every step that did not diverge is followed by, at simulated
    /// time `t`: the live error against the reference when due, and the
    /// loop back to the start.
    fn after_step(&mut self, t: f64) {
        if let Some(sh) = self.shadow.as_mut() {
            // Once per reference metric frame interval, compare with the
            // reference interpolated linearly to this step's time (frame f
            // of the recording is at time (f + 1)·interval); in a touched
            // episode, hand the state to the replica instead and take the
            // newest error it has returned.
            if sh.due(t) {
                if !self.touched_episode {
                    self.live_error = sh.error_at(t, &self.sim.state().pos, self.cloud.as_mut());
                    self.live_error_time = self.live_error.map(|_| t);
                } else if let (Some(replica), Some(problem)) = (self.replica.as_mut(), sh.problem()) {
                    replica.compare(t, problem, &self.sim.state().pos);
                    self.poll_replica();
                }
            }
        }
        if self.looping && t >= self.duration && !self.touched() {
            self.restart();
        }
    }
}

/// Steps a pass may take to catch up `max_catch_up` simulated seconds at
/// `dt` (at least one: an instance always advances).
fn catch_up_steps(max_catch_up: f64, dt: f64) -> u64 {
    ((max_catch_up / dt) as u64).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use crate::sim::Serial;

    /// A runner of the hanging scene at 8×8 with dt = 0.25 ms (64 steps are
    /// 16 ms: the old bound in steps), catching up at most 0.1 s a pass.
    fn runner() -> Runner {
        let mut scene = Scene::load(std::path::Path::new("config/scenes/hanging.toml")).expect("scene");
        scene.params.dt = 0.25e-3;
        let sim = scene.build_at(8, 8).expect("builds");
        assert!(sim.dt_limit() > sim.params().dt, "dt within the stability limit");
        let (_tx, rx) = std::sync::mpsc::channel();
        let settings = EngineSettings {
            threads: 1,
            max_catch_up: 0.1,
            max_lag: 0.25,
            metrics_hz: 10.0,
            replay_class: || {},
        };
        let setup = InstanceSetup {
            publish_hz: 60.0,
            ..InstanceSetup::new("hanging", sim, Level::new(8, 8))
        };
        Runner::new(setup, rx, settings).0
    }

    /// Steps due `ms` milliseconds after the origin at dt = 0.25 ms.
    fn due(ms: u64) -> u64 {
        ms * 4
    }

    /// A stall of the machine (the thread's pass comes 40 ms late, 160
    /// steps) is caught up in one pass without an overrun, whatever the
    /// instance's dt; a pass 150 ms further behind than that is an overrun,
    /// takes 0.1 s of it and carries the rest to the next pass (no step is
    /// lost), and a backlog past `max_lag` is dropped. With the bound of 64
    /// steps a pass the first pass overran.
    #[test]
    fn a_pass_catches_up_a_stall_in_simulated_time() {
        let mut r = runner();
        let t0 = r.origin;
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        r.advance(at(40), &Serial);
        assert_eq!((r.steps_since_origin, r.overruns), (due(40), 0), "a 40 ms stall");
        r.advance(at(190), &Serial);
        assert_eq!(r.overruns, 1, "150 ms behind is more than 0.1 s");
        assert_eq!(r.steps_since_origin, due(40) + due(100), "0.1 s caught up");
        r.advance(at(190), &Serial);
        assert_eq!(
            (r.steps_since_origin, r.overruns),
            (due(190), 1),
            "the rest in the next pass"
        );
        assert_eq!(r.lag_resets, 0);
        r.advance(at(500), &Serial);
        assert_eq!((r.lag_resets, r.steps_since_origin), (1, 1), "310 ms behind: dropped");
        assert_eq!(r.sim.state().step, due(190) + 1, "every step taken was kept");
    }
}
