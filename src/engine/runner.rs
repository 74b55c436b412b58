//! One instance on its stepping thread: what it runs, pacing to the wall
//! clock ([`Pacing`]), and the step itself. Commands, switches, inputs,
//! the live error, divergence and publishing are the other stages of the
//! same `impl`, one file each; each stage's state is its own struct
//! ([`Inputs`], [`LiveError`], [`Divergence`], [`Publishing`]), changed
//! through its methods.

use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::{Duration, Instant};

use super::divergence::{is_diverged, Divergence};
use super::input::Inputs;
use super::live::LiveError;
use super::publish::Publishing;
use super::{Command, EngineSettings, HandleParts, InstanceSetup, Status};
use crate::estimate::Method;
use crate::plan::Level;
use crate::points::cloud::CloudMap;
use crate::sim::{Material, Pair, Simulation};

/// One instance on its stepping thread: the simulation and what it runs
/// (level, method, coefficients), and the stages that act on it, each
/// owning its own state.
pub(super) struct Runner {
    pub(super) name: String,
    pub(super) sim: Simulation,
    pub(super) cloud: Option<CloudMap>,
    pub(super) level: Level,
    pub(super) method: Method,
    pub(super) material: Material,
    pub(super) predicted_error: Option<f64>,
    pub(super) coefficient_version: u32,
    /// Steps taken (a restore sets it to the snapshot's).
    pub(super) frames: u64,
    /// Times the scene started over (a restore sets it to the snapshot's).
    pub(super) episode: u64,
    /// Scene duration (s): the scene starts over there when `looping`.
    pub(super) duration: f64,
    pub(super) looping: bool,
    /// See [`InstanceSetup::switch_settle`].
    pub(super) switch_settle: Option<f64>,
    pub(super) commands: Receiver<Command>,
    pub(super) pacing: Pacing,
    pub(super) live: LiveError,
    pub(super) inputs: Inputs,
    pub(super) divergence: Divergence,
    pub(super) publishing: Publishing,
}

/// Pacing to the wall clock: step `steps_since_origin` is due at
/// origin + steps·dt; what could not keep up is counted.
pub(super) struct Pacing {
    origin: Instant,
    steps_since_origin: u64,
    paused: bool,
    /// Waiting for a [`Command::Restore`]: no steps, no states.
    held: bool,
    overruns: u64,
    /// Passes of its thread that woke more than [`super::STALL`] late.
    stalls: u64,
    lag_resets: u64,
    /// See [`EngineSettings::max_catch_up`].
    max_catch_up: f64,
    /// See [`EngineSettings::max_lag`].
    max_lag: f64,
    /// See [`EngineSettings::slice`].
    slice: Duration,
}

impl Pacing {
    fn new(now: Instant, held: bool, settings: &EngineSettings) -> Pacing {
        Pacing {
            origin: now,
            steps_since_origin: 0,
            paused: false,
            held,
            overruns: 0,
            stalls: 0,
            lag_resets: 0,
            max_catch_up: settings.max_catch_up,
            max_lag: settings.max_lag,
            slice: settings.slice,
        }
    }

    pub(super) fn paused(&self) -> bool {
        self.paused
    }

    pub(super) fn set_paused(&mut self, paused: bool) {
        self.paused = paused;
    }

    pub(super) fn held(&self) -> bool {
        self.held
    }

    /// The [`Command::Restore`] came: stepping may start.
    pub(super) fn release(&mut self) {
        self.held = false;
    }

    /// Paused or held: no steps are due.
    fn stopped(&self) -> bool {
        self.paused || self.held
    }

    pub(super) fn overruns(&self) -> u64 {
        self.overruns
    }

    pub(super) fn stalls(&self) -> u64 {
        self.stalls
    }

    pub(super) fn lag_resets(&self) -> u64 {
        self.lag_resets
    }

    /// The thread's pass came more than [`super::STALL`] late.
    pub(super) fn stalled(&mut self) {
        self.stalls += 1;
    }

    /// Count steps from `now`: what was not taken by then is never due.
    pub(super) fn reanchor(&mut self, now: Instant) {
        self.origin = now;
        self.steps_since_origin = 0;
    }

    /// When the next step of `dt` is due; `None` while stopped.
    fn next_step(&self, dt: f64) -> Option<Instant> {
        (!self.stopped()).then(|| self.origin + Duration::from_secs_f64((self.steps_since_origin + 1) as f64 * dt))
    }

    /// Steps of `dt` to take at `now`: the backlog dropped past `max_lag`
    /// (a lag reset), at most `max_catch_up` of it (an overrun when that is
    /// not all of it).
    fn steps_due(&mut self, now: Instant, dt: f64, name: &str) -> u64 {
        let elapsed = now.saturating_duration_since(self.origin).as_secs_f64();
        let mut due = ((elapsed / dt) as u64).saturating_sub(self.steps_since_origin);
        if due as f64 * dt > self.max_lag {
            self.lag_resets += 1;
            tracing::warn!(instance = %name, behind_s = due as f64 * dt, "fell behind real time; dropping the backlog");
            self.reanchor(now);
            due = 1;
        }
        let n = due.min(catch_up_steps(self.max_catch_up, dt));
        if due > n {
            self.overruns += 1;
        }
        n
    }

    /// A pass took the `n` steps it found due.
    fn stepped(&mut self, n: u64) {
        self.steps_since_origin += n;
    }
}

impl Runner {
    pub(super) fn new(
        setup: InstanceSetup,
        commands: Receiver<Command>,
        settings: EngineSettings,
    ) -> (Runner, HandleParts) {
        let now = Instant::now();
        let material = setup.sim.params().material;
        let status = Status {
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
        };
        let (publishing, parts) = Publishing::new(
            setup.name.clone(),
            status,
            now,
            Duration::from_secs_f64(1.0 / setup.publish_hz),
            Duration::from_secs_f64(1.0 / settings.metrics_hz),
        );
        let runner = Runner {
            name: setup.name,
            level: setup.level,
            method: setup.method,
            material,
            predicted_error: None,
            coefficient_version: 1,
            frames: 0,
            episode: 0,
            duration: setup.duration,
            looping: setup.looping,
            switch_settle: setup.switch_settle,
            commands,
            pacing: Pacing::new(now, setup.hold, &settings),
            live: LiveError::new(setup.shadow, settings.replay_class),
            inputs: Inputs::new(setup.touch, now, Duration::from_secs_f64(setup.input_idle)),
            divergence: Divergence::new(setup.sim.state().clone()),
            publishing,
            sim: setup.sim,
            cloud: setup.cloud,
        };
        (runner, parts)
    }

    pub(super) fn dt(&self) -> f64 {
        self.sim.params().dt
    }

    /// When the next step is due.
    pub(super) fn next_due(&self) -> Instant {
        match self.pacing.next_step(self.dt()) {
            Some(due) => due,
            None => self.publishing.next_metrics(),
        }
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

    /// Take the steps due at `now`, for at most the pass's slice of wall
    /// time (and one step); returns how many it took.
    pub(super) fn advance(&mut self, now: Instant, pair: &dyn Pair) -> u64 {
        if self.pacing.stopped() {
            self.pacing.reanchor(now);
            return 0;
        }
        self.let_go_if_idle(now);
        let dt = self.dt();
        let n = self.pacing.steps_due(now, dt, &self.name);
        if n == 0 {
            return 0;
        }
        let t0 = Instant::now();
        let mut taken = 0;
        while taken < n {
            // The pass's last step is a full one (see `step_once`), also
            // when the slice ends the pass before every due step is taken.
            let last = taken + 1 == n || t0.elapsed() >= self.pacing.slice;
            self.step_once(pair, last);
            taken += 1;
            if last || self.pacing.paused() {
                break;
            }
        }
        self.publishing.count_steps(t0.elapsed(), taken, taken as f64 * dt);
        self.pacing.stepped(taken);
        taken
    }

    /// One step. `last`: the tick's last, whose report the metrics show. The
    /// others are lean (`Simulation::step_on_lean`: no spring energy or
    /// strain, 9–16 % of a 64×64 step): finiteness is checked every step,
    /// the strain on the tick's last step and before a checkpoint is taken,
    /// so no checkpoint holds a state that was not checked whole.
    pub(super) fn step_once(&mut self, pair: &dyn Pair, last: bool) {
        let checkpoint_due = self.divergence.checkpoint_due(self.sim.state().time + self.dt());
        let full = last || checkpoint_due;
        let report = if full {
            self.sim.step_on(pair)
        } else {
            self.sim.step_on_lean(pair)
        };
        self.frames += 1;
        if is_diverged(&report, full) {
            self.diverged(report.time);
            return;
        }
        if full {
            self.publishing.show(report);
            self.divergence.checkpoint_if_due(report.time, self.sim.state());
        }
        self.after_step(report.time);
    }

    /// What every step that did not diverge is followed by, at simulated
    /// time `t`: the live error against the reference when due, and the
    /// loop back to the start.
    fn after_step(&mut self, t: f64) {
        let touched_episode = self.inputs.touched_episode();
        self.live.compare(
            &self.name,
            t,
            touched_episode,
            &self.sim.state().pos,
            self.cloud.as_mut(),
        );
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
            // No pass is cut short here: the test is of catching up.
            slice: Duration::from_secs(60),
            metrics_hz: 10.0,
            replay_class: || {},
        };
        let setup = InstanceSetup {
            publish_hz: 60.0,
            ..InstanceSetup::new("hanging", sim, Level::new(8, 8))
        };
        Runner::new(setup, rx, settings).0
    }

    /// A pass ends at its slice, its last step a full one, and leaves the
    /// rest due for the next pass without counting an overrun.
    #[test]
    fn a_pass_ends_at_its_slice_and_leaves_the_rest_due() {
        let mut r = runner();
        r.pacing.slice = Duration::ZERO;
        let t0 = r.pacing.origin;
        let at = t0 + Duration::from_millis(40);
        assert_eq!(r.advance(at, &Serial), 1, "one step in a slice of nothing");
        assert_eq!(r.advance(at, &Serial), 1);
        assert_eq!((r.pacing.steps_since_origin, r.pacing.overruns), (2, 0));
        assert_eq!(
            r.publishing.last.map(|rep| rep.step),
            Some(2),
            "the pass's step was a full one"
        );
        r.pacing.slice = Duration::from_secs(60);
        assert_eq!(r.advance(at, &Serial), due(40) - 2, "the rest in the next pass");
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
        let t0 = r.pacing.origin;
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        r.advance(at(40), &Serial);
        let p = |r: &Runner| (r.pacing.steps_since_origin, r.pacing.overruns, r.pacing.lag_resets);
        r.advance(at(40), &Serial);
        assert_eq!(p(&r), (due(40), 0, 0), "a 40 ms stall");
        r.advance(at(190), &Serial);
        assert_eq!(p(&r).1, 1, "150 ms behind is more than 0.1 s");
        assert_eq!(p(&r).0, due(40) + due(100), "0.1 s caught up");
        r.advance(at(190), &Serial);
        assert_eq!(p(&r), (due(190), 1, 0), "the rest in the next pass");
        r.advance(at(500), &Serial);
        assert_eq!((p(&r).2, p(&r).0), (1, 1), "310 ms behind: dropped");
        assert_eq!(r.sim.state().step, due(190) + 1, "every step taken was kept");
    }
}
