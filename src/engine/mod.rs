//! The stepping engine: the only code that knows threads and the wall clock.
//!
//! Instances are spread over a fixed set of OS threads (one per core by
//! default; never tokio workers). Each thread runs its instances at their
//! fixed dt, paced to the wall clock: simulated time tracks real time; an
//! instance that runs late catches up with at most `max_substeps` steps per
//! pass (counting an overrun when that is not enough) and, beyond `max_lag`
//! behind, drops the backlog (a lag reset). dt is never stretched.
//!
//! Commands (switch, pause, reset) arrive on a channel and are applied
//! between steps. States and metrics leave through `watch` channels that
//! hold only the newest value, so a slow publisher drops frames and never
//! blocks stepping. The two states at a level switch (old level, new level,
//! same instant) also go through a small unbounded channel so that both
//! reach the bus.

mod shadow;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use tokio::sync::{oneshot, watch};

use crate::estimate::Method;
use crate::lod::transfer_state;
use crate::plan::{Level, Prepared};
use crate::points::cloud::CloudMap;
use crate::sim::vec3::V3;
use crate::sim::{Material, Simulation, State, StepReport, Topology};
use shadow::Shadow;

/// A snapshot of an instance's cloth, as the engine hands it to the bus.
#[derive(Debug, Clone)]
pub struct StateFrame {
    pub frame: u64,
    pub time: f64,
    pub episode: u64,
    pub level: Level,
    pub coefficient_version: u32,
    /// Interleaved x, y, z per node (a surface: per point of the full cloud).
    pub positions: Vec<f32>,
    /// Surfaces: the simulated points and the cloud's normals, interleaved
    /// (empty for a cloth).
    pub simulation_positions: Vec<f32>,
    pub normals: Vec<f32>,
    /// The shadow reference at `time`, laid out like `positions` (empty
    /// without a shadow reference or outside its recording).
    pub reference_positions: Vec<f32>,
    pub stepped: SystemTime,
    pub transition: bool,
}

/// Metrics over the last interval.
#[derive(Debug, Clone)]
pub struct MetricsFrame {
    pub frame: u64,
    pub time: f64,
    pub level: Level,
    pub method: Method,
    pub predicted_error: Option<f64>,
    pub live_error: Option<f64>,
    pub step_cost_us: f64,
    pub real_time_factor: f64,
    pub overruns: u64,
    pub lag_resets: u64,
    pub divergences: u64,
    /// Divergences answered by rolling back to the last checkpoint.
    pub rollbacks: u64,
    /// Why the instance stopped stepping (it kept diverging); `None` while
    /// it steps.
    pub halted: Option<Arc<str>>,
    pub kinetic_energy: f64,
    pub potential_energy: f64,
    pub max_strain: f64,
    pub coefficient_version: u32,
    pub paused: bool,
    pub dt: f64,
}

/// What `info` replies describe: updated at every switch, pause and reset.
#[derive(Debug, Clone)]
pub struct Status {
    pub level: Level,
    pub method: Method,
    pub material: Material,
    pub dt: f64,
    pub coefficient_version: u32,
    pub predicted_error: Option<f64>,
    pub paused: bool,
    /// See [`MetricsFrame::halted`].
    pub halted: Option<Arc<str>>,
    pub topology: Arc<Topology>,
    pub pinned: Vec<u32>,
    pub frame: u64,
    pub o_max: Option<f64>,
    /// Surfaces: cloud index of each simulated point, and the cloud size.
    pub simulation_points: Option<Arc<Vec<u32>>>,
    pub cloud_points: usize,
}

/// A level switch done.
#[derive(Debug, Clone)]
pub struct SwitchOutcome {
    pub previous: Level,
    pub level: Level,
    pub method: Method,
    pub material: Material,
    pub predicted_error: Option<f64>,
    pub dt: f64,
    pub coefficient_version: u32,
    pub frame: u64,
}

/// State after a control command.
#[derive(Debug, Clone, Copy)]
pub struct ControlOutcome {
    pub paused: bool,
    pub frame: u64,
}

/// What an instance needs to resume where it was (the service persists it;
/// see `service::snapshot`).
#[derive(Debug, Clone)]
pub struct Snapshot {
    pub level: Level,
    pub method: Method,
    pub coefficient_version: u32,
    pub frame: u64,
    pub episode: u64,
    pub paused: bool,
    /// The full state, in f64 (a surface: its simulated points).
    pub state: State,
    /// The coefficients and time step it ran with: a cloth resumes with
    /// them at once instead of waiting for its level to be prepared again
    /// (None in files written before they were saved).
    pub coefficients: Option<Coefficients>,
}

/// What a level ran with: enough to rebuild its simulation without its
/// reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coefficients {
    pub material: Material,
    /// The time step (s).
    pub dt: f64,
}

/// Commands, applied between steps.
pub enum Command {
    /// Continue at `prepared`'s level from the current state (transferred).
    /// `sim` is the new level at rest, built off the stepping thread.
    Switch {
        prepared: Arc<Prepared>,
        sim: Box<Simulation>,
        /// Surfaces: the new level's cloud map (built off the stepping thread too).
        cloud: Option<Box<CloudMap>>,
        reply: oneshot::Sender<Result<SwitchOutcome, String>>,
    },
    Pause {
        paused: bool,
        reply: oneshot::Sender<ControlOutcome>,
    },
    /// Start the scene over from rest at the current level.
    Reset { reply: oneshot::Sender<ControlOutcome> },
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
        reply: oneshot::Sender<Result<(), String>>,
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

/// Everything an instance starts with.
pub struct InstanceSetup {
    pub name: String,
    pub sim: Simulation,
    /// Surfaces: how the simulated points move the cloud.
    pub cloud: Option<CloudMap>,
    pub level: Level,
    pub method: Method,
    pub publish_hz: f64,
    /// Scene duration (s): the scene starts over there when `looping`.
    pub duration: f64,
    pub looping: bool,
    /// Compare with the recorded reference and publish the live error.
    pub shadow: bool,
    /// Neither step nor publish until a [`Command::Restore`] (a snapshot is
    /// being prepared to resume from).
    pub hold: bool,
}

/// The service's side of one running instance.
#[derive(Clone)]
pub struct InstanceHandle {
    pub name: String,
    commands: Sender<Command>,
    thread: std::thread::Thread,
    pub states: watch::Receiver<Option<Arc<StateFrame>>>,
    pub metrics: watch::Receiver<Option<Arc<MetricsFrame>>>,
    pub transitions: Arc<tokio::sync::Mutex<tokio::sync::mpsc::UnboundedReceiver<Arc<StateFrame>>>>,
    status: Arc<Mutex<Status>>,
}

impl InstanceHandle {
    /// Queue a command and wake the instance's thread. Err when the engine
    /// has stopped.
    pub fn send(&self, command: Command) -> Result<(), &'static str> {
        self.commands.send(command).map_err(|_| "the engine has stopped")?;
        self.thread.unpark();
        Ok(())
    }

    pub fn status(&self) -> Status {
        lock(&self.status).clone()
    }
}

/// How the engine paces its instances (validated from the config's
/// `[engine]` section by the service).
#[derive(Debug, Clone, Copy)]
pub struct EngineSettings {
    /// Stepping threads (at most one per instance is used).
    pub threads: usize,
    /// Steps an instance may take in one pass to catch up with the wall
    /// clock; a pass that needs more counts an overrun.
    pub max_substeps: u32,
    /// Seconds an instance may fall behind the wall clock before its
    /// backlog is dropped (a lag reset).
    pub max_lag: f64,
    /// Metrics published per second per instance.
    pub metrics_hz: f64,
}

/// The running engine.
pub struct Engine {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    handles: Vec<InstanceHandle>,
}

impl Engine {
    /// Start stepping `instances`, spread over `settings.threads` threads by
    /// their cost (nodes / dt, heavier integrators weighted up).
    pub fn start(instances: Vec<InstanceSetup>, settings: EngineSettings) -> std::io::Result<Engine> {
        let stop = Arc::new(AtomicBool::new(false));
        let n_threads = settings.threads.clamp(1, instances.len().max(1));
        let mut buckets: Vec<(f64, Vec<Runner>)> = (0..n_threads).map(|_| (0.0, Vec::new())).collect();
        // Heaviest first onto the least loaded thread; handles come back in
        // the caller's order.
        let mut order: Vec<(usize, InstanceSetup)> = instances.into_iter().enumerate().collect();
        order.sort_by(|a, b| cost(&b.1).total_cmp(&cost(&a.1)));
        let mut receivers = Vec::new();
        let mut pending = Vec::new();
        for (index, setup) in order {
            let c = cost(&setup);
            let (tx, rx) = mpsc::channel();
            let (runner, handle_parts) = Runner::new(setup, rx, settings);
            let b = (0..n_threads)
                .min_by(|&i, &j| buckets[i].0.total_cmp(&buckets[j].0))
                .unwrap_or(0);
            buckets[b].0 += c;
            buckets[b].1.push(runner);
            receivers.push(b);
            pending.push((index, tx, handle_parts));
        }
        let mut threads = Vec::new();
        for (i, (_, runners)) in buckets.into_iter().enumerate() {
            let stop = stop.clone();
            let h = std::thread::Builder::new()
                .name(format!("lodcloth-step-{i}"))
                .spawn(move || worker(runners, stop, settings))?;
            threads.push(h);
        }
        let mut handles: Vec<(usize, InstanceHandle)> = pending
            .into_iter()
            .zip(receivers)
            .map(|((index, tx, parts), b)| {
                (
                    index,
                    InstanceHandle {
                        name: parts.name,
                        commands: tx,
                        thread: threads[b].thread().clone(),
                        states: parts.states,
                        metrics: parts.metrics,
                        transitions: Arc::new(tokio::sync::Mutex::new(parts.transitions)),
                        status: parts.status,
                    },
                )
            })
            .collect();
        handles.sort_by_key(|(i, _)| *i);
        let handles = handles.into_iter().map(|(_, h)| h).collect();
        Ok(Engine { stop, threads, handles })
    }

    pub fn handles(&self) -> &[InstanceHandle] {
        &self.handles
    }

    /// Finish the current steps and join every thread.
    pub fn stop(self) {
        self.stop.store(true, Ordering::SeqCst);
        for t in &self.threads {
            t.thread().unpark();
        }
        for t in self.threads {
            if t.join().is_err() {
                tracing::error!("a stepping thread panicked");
            }
        }
    }
}

/// Relative cost of one simulated second.
fn cost(s: &InstanceSetup) -> f64 {
    let p = s.sim.params();
    let per_step = match p.integrator {
        crate::sim::Integrator::Rk4 => 4.5,
        crate::sim::Integrator::ImplicitEuler => 25.0,
        _ => 1.0,
    };
    s.sim.topology().n_nodes as f64 * per_step / p.dt
}

struct HandleParts {
    name: String,
    states: watch::Receiver<Option<Arc<StateFrame>>>,
    metrics: watch::Receiver<Option<Arc<MetricsFrame>>>,
    transitions: tokio::sync::mpsc::UnboundedReceiver<Arc<StateFrame>>,
    status: Arc<Mutex<Status>>,
}

/// One instance on its stepping thread.
struct Runner {
    name: String,
    sim: Simulation,
    cloud: Option<CloudMap>,
    level: Level,
    method: Method,
    material: Material,
    predicted_error: Option<f64>,
    coefficient_version: u32,
    shadow: Option<Shadow>,
    shadow_wanted: bool,
    live_error: Option<f64>,
    /// The reference's largest displacement, once calibrated.
    o_max: Option<f64>,
    duration: f64,
    looping: bool,
    commands: Receiver<Command>,
    settings: EngineSettings,
    // Pacing: step `steps_since_origin` is due at origin + steps·dt.
    origin: Instant,
    steps_since_origin: u64,
    paused: bool,
    frames: u64,
    episode: u64,
    overruns: u64,
    lag_resets: u64,
    divergences: u64,
    // Divergence recovery: a finite state at most CHECKPOINT_INTERVAL of
    // simulated time old, rolled back to when a step diverges.
    checkpoint: State,
    rollbacks: u64,
    /// Divergences since the last CLEAN_INTERVAL of clean stepping.
    consecutive_divergences: u32,
    last_divergence_time: f64,
    halted: Option<Arc<str>>,
    /// Waiting for a [`Command::Restore`]: no steps, no states.
    held: bool,
    last: Option<StepReport>,
    // Metrics window.
    window_start: Instant,
    window_sim: f64,
    window_steps: u64,
    window_busy: Duration,
    next_publish: Instant,
    publish_every: Duration,
    next_metrics: Instant,
    metrics_every: Duration,
    states: watch::Sender<Option<Arc<StateFrame>>>,
    metrics: watch::Sender<Option<Arc<MetricsFrame>>>,
    transitions: tokio::sync::mpsc::UnboundedSender<Arc<StateFrame>>,
    status: Arc<Mutex<Status>>,
}

impl Runner {
    fn new(setup: InstanceSetup, commands: Receiver<Command>, settings: EngineSettings) -> (Runner, HandleParts) {
        let now = Instant::now();
        let (states_tx, states_rx) = watch::channel(None);
        let (metrics_tx, metrics_rx) = watch::channel(None);
        let (trans_tx, trans_rx) = tokio::sync::mpsc::unbounded_channel();
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
            status: status.clone(),
        };
        let parts = HandleParts {
            name: setup.name,
            states: states_rx,
            metrics: metrics_rx,
            transitions: trans_rx,
            status,
        };
        (runner, parts)
    }

    fn dt(&self) -> f64 {
        self.sim.params().dt
    }

    /// When the next step is due.
    fn next_due(&self) -> Instant {
        if self.paused || self.held {
            return self.next_metrics;
        }
        self.origin + Duration::from_secs_f64((self.steps_since_origin + 1) as f64 * self.dt())
    }

    fn reanchor(&mut self, now: Instant) {
        self.origin = now;
        self.steps_since_origin = 0;
    }

    /// Apply queued commands.
    fn poll_commands(&mut self) {
        loop {
            match self.commands.try_recv() {
                Ok(c) => self.apply(c),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => return,
            }
        }
    }

    fn apply(&mut self, command: Command) {
        match command {
            Command::Switch {
                prepared,
                sim,
                cloud,
                reply,
            } => {
                let outcome = self.switch(prepared, *sim, cloud.map(|c| *c));
                let _ = reply.send(outcome);
            }
            Command::Pause { paused, reply } => {
                if !paused && self.halted.is_some() {
                    // Resuming a halted instance starts its scene over.
                    self.halted = None;
                    self.consecutive_divergences = 0;
                    self.restart();
                }
                self.paused = paused;
                self.reanchor(Instant::now());
                self.update_status();
                let _ = reply.send(ControlOutcome {
                    paused,
                    frame: self.frames,
                });
            }
            Command::Reset { reply } => {
                self.halted = None;
                self.consecutive_divergences = 0;
                self.restart();
                self.reanchor(Instant::now());
                let _ = reply.send(ControlOutcome {
                    paused: self.paused,
                    frame: self.frames,
                });
            }
            Command::Snapshot { reply } => {
                let snapshot = (!self.held && self.halted.is_none()).then(|| {
                    Box::new(Snapshot {
                        level: self.level,
                        method: self.method,
                        coefficient_version: self.coefficient_version,
                        frame: self.frames,
                        episode: self.episode,
                        paused: self.paused,
                        state: self.sim.state().clone(),
                        coefficients: Some(Coefficients {
                            material: self.material,
                            dt: self.dt(),
                        }),
                    })
                });
                let _ = reply.send(snapshot);
            }
            Command::Restore {
                prepared,
                sim,
                cloud,
                saved,
                reply,
            } => {
                let outcome = match saved {
                    Some(saved) if self.held => self.restore(prepared, sim.map(|s| *s), cloud.map(|c| *c), *saved),
                    Some(_) => Err("the instance is already running".into()),
                    None => Ok(()),
                };
                self.held = false;
                self.reanchor(Instant::now());
                self.update_status();
                let _ = reply.send(outcome);
            }
            Command::Attach {
                prepared,
                coefficient_version,
                reply,
            } => {
                let same = self.level == prepared.level
                    && self.method == prepared.method
                    && self.coefficient_version == coefficient_version
                    && self.material == prepared.material
                    && self.dt() == prepared.dt
                    && self.predicted_error.is_none();
                if same {
                    self.predicted_error = Some(prepared.predicted_error);
                    self.o_max = Some(prepared.o_max);
                    self.shadow = self
                        .shadow_wanted
                        .then(|| Shadow::new(prepared.clone(), self.sim.topology().n_nodes));
                    self.update_status();
                }
                let _ = reply.send(same);
            }
        }
    }

    /// Resume `saved`: its state, frame, episode and pause, at `prepared`'s
    /// level and coefficients (or the current ones).
    fn restore(
        &mut self,
        prepared: Option<Arc<Prepared>>,
        sim: Option<Simulation>,
        cloud: Option<CloudMap>,
        saved: Snapshot,
    ) -> Result<(), String> {
        let level = match (&prepared, &sim) {
            (Some(p), _) => p.level,
            (None, Some(_)) => saved.level,
            (None, None) => self.level,
        };
        if saved.level != level {
            return Err(format!("the snapshot is at {}, the simulation at {level}", saved.level));
        }
        match (prepared, sim) {
            (Some(prepared), Some(mut sim)) => {
                sim.set_state(saved.state).map_err(|e| e.to_string())?;
                self.sim = sim;
                if cloud.is_some() {
                    self.cloud = cloud;
                }
                self.method = prepared.method;
                self.material = prepared.material;
                self.predicted_error = Some(prepared.predicted_error);
                self.o_max = Some(prepared.o_max);
                self.shadow = self
                    .shadow_wanted
                    .then(|| Shadow::new(prepared.clone(), self.sim.topology().n_nodes));
            }
            (None, Some(mut sim)) => {
                let Some(saved_with) = saved.coefficients else {
                    return Err("a restore without a prepared level needs the snapshot's coefficients".into());
                };
                if sim.params().material != saved_with.material || sim.params().dt != saved_with.dt {
                    return Err("the simulation was not built with the snapshot's coefficients".into());
                }
                sim.set_state(saved.state).map_err(|e| e.to_string())?;
                self.sim = sim;
                self.method = saved.method;
                self.material = saved_with.material;
                self.predicted_error = None;
                self.o_max = None;
                self.shadow = None;
            }
            (None, None) => self.sim.set_state(saved.state).map_err(|e| e.to_string())?,
            (Some(_), None) => return Err("a restore needs both the prepared level and its simulation".into()),
        }
        self.level = level;
        self.coefficient_version = saved.coefficient_version;
        self.frames = saved.frame;
        self.episode = saved.episode;
        self.paused = saved.paused;
        self.checkpoint.clone_from(self.sim.state());
        self.live_error = None;
        Ok(())
    }

    fn switch(
        &mut self,
        prepared: Arc<Prepared>,
        mut sim: Simulation,
        cloud: Option<CloudMap>,
    ) -> Result<SwitchOutcome, String> {
        let previous = self.level;
        let old_topology = self.sim.topology().clone();
        let before = self.snapshot(true);
        let state = match (self.cloud.as_mut(), cloud.as_ref()) {
            (Some(from), Some(to)) => from.carry(self.sim.state(), to),
            (None, None) => {
                if Arc::ptr_eq(&old_topology, sim.topology()) || old_topology.n_nodes == sim.topology().n_nodes {
                    self.sim.state().clone()
                } else {
                    transfer_state(&old_topology, self.sim.state(), sim.topology()).map_err(|e| e.to_string())?
                }
            }
            _ => return Err("a switch between a cloth and a surface level".into()),
        };
        sim.set_state(state).map_err(|e| e.to_string())?;
        self.sim = sim;
        self.checkpoint = self.sim.state().clone();
        self.consecutive_divergences = 0;
        if cloud.is_some() {
            self.cloud = cloud;
        }
        self.level = prepared.level;
        self.method = prepared.method;
        self.material = prepared.material;
        self.predicted_error = Some(prepared.predicted_error);
        self.o_max = Some(prepared.o_max);
        self.coefficient_version += 1;
        self.shadow = self
            .shadow_wanted
            .then(|| Shadow::new(prepared.clone(), self.sim.topology().n_nodes));
        self.live_error = None;
        self.reanchor(Instant::now());
        self.update_status();
        let after = self.snapshot(true);
        let _ = self.transitions.send(Arc::new(before));
        let after = Arc::new(after);
        let _ = self.transitions.send(after.clone());
        self.states.send_replace(Some(after));
        Ok(SwitchOutcome {
            previous,
            level: self.level,
            method: self.method,
            material: self.material,
            predicted_error: self.predicted_error,
            dt: self.dt(),
            coefficient_version: self.coefficient_version,
            frame: self.frames,
        })
    }

    /// Back to rest at the current level; a new episode.
    fn restart(&mut self) {
        let rest = State::at_rest(self.sim.topology());
        if let Err(e) = self.sim.set_state(rest) {
            tracing::error!(instance = %self.name, "reset failed: {e}");
        }
        self.episode += 1;
        self.live_error = None;
        self.checkpoint.clone_from(self.sim.state());
        self.update_status();
    }

    /// A step came out non-finite or absurdly stretched: roll back to the
    /// checkpoint, or after
    /// [`MAX_CONSECUTIVE_DIVERGENCES`] without a clean stretch between
    /// them, stop stepping (paused, with the reason in metrics and info).
    fn diverged(&mut self, time: f64) {
        self.divergences += 1;
        self.consecutive_divergences += 1;
        self.last_divergence_time = self.checkpoint.time;
        if let Err(e) = self.sim.set_state(self.checkpoint.clone()) {
            tracing::error!(instance = %self.name, "rolling back failed: {e}; starting the scene over");
            self.restart();
        }
        self.live_error = None;
        if self.consecutive_divergences >= MAX_CONSECUTIVE_DIVERGENCES {
            let reason = format!(
                "diverged {} times in a row (last at t = {time:.3} s, level {}, dt {:.3e} s, {} integrator): \
                 stopped; resume or reset starts the scene over (switch first to restart at another level)",
                self.consecutive_divergences,
                self.level,
                self.dt(),
                self.sim.params().integrator.name()
            );
            tracing::error!(instance = %self.name, divergences = self.divergences, "{reason}");
            self.halted = Some(reason.into());
            self.paused = true;
        } else {
            self.rollbacks += 1;
            tracing::error!(
                instance = %self.name,
                level = %self.level,
                time,
                rolled_back_to = self.checkpoint.time,
                "the simulation diverged; rolled back to the last checkpoint"
            );
        }
        self.update_status();
    }

    fn update_status(&self) {
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
    fn advance(&mut self, now: Instant) {
        if self.paused || self.held {
            self.reanchor(now);
            return;
        }
        let dt = self.dt();
        let elapsed = now.saturating_duration_since(self.origin).as_secs_f64();
        let mut due = ((elapsed / dt) as u64).saturating_sub(self.steps_since_origin);
        if due as f64 * dt > self.settings.max_lag {
            self.lag_resets += 1;
            tracing::warn!(instance = %self.name, behind_s = due as f64 * dt, "fell behind real time; dropping the backlog");
            self.reanchor(now);
            due = 1;
        }
        let n = due.min(u64::from(self.settings.max_substeps));
        if due > n {
            self.overruns += 1;
        }
        if n == 0 {
            return;
        }
        let t0 = Instant::now();
        for _ in 0..n {
            self.step_once();
            if self.paused {
                break;
            }
        }
        self.window_busy += t0.elapsed();
        self.window_steps += n;
        self.window_sim += n as f64 * dt;
        self.steps_since_origin += n;
    }

    fn step_once(&mut self) {
        let report = self.sim.step();
        self.frames += 1;
        // Non-finite, or finite but absurd (springs at 11× their rest
        // length: positions soon overflow f32 on the wire).
        if !report.finite || report.max_strain_overall() > DIVERGED_STRAIN {
            self.diverged(report.time);
            return;
        }
        self.last = Some(report);
        if report.time >= self.checkpoint.time + CHECKPOINT_INTERVAL {
            // In place: no allocation once the buffers have their size.
            self.checkpoint.clone_from(self.sim.state());
            if report.time >= self.last_divergence_time + CLEAN_INTERVAL {
                self.consecutive_divergences = 0;
            }
        }
        if let Some(sh) = self.shadow.as_mut() {
            // Once per reference metric frame interval, compare with the
            // reference interpolated linearly to this step's time (frame f
            // of the recording is at time (f + 1)·interval).
            let t = report.time;
            if sh.due(t) {
                self.live_error = sh.error_at(t, &self.sim.state().pos, self.cloud.as_mut());
            }
        }
        if self.looping && report.time >= self.duration {
            self.restart();
        }
    }

    fn snapshot(&mut self, transition: bool) -> StateFrame {
        let s = self.sim.state();
        let n = s.n_nodes();
        let mut nodes = Vec::with_capacity(3 * n);
        for k in 0..n {
            nodes.extend_from_slice(&[s.pos[k] as f32, s.pos[n + k] as f32, s.pos[2 * n + k] as f32]);
        }
        let (positions, simulation_positions, normals) = match self.cloud.as_mut() {
            None => (nodes, Vec::new(), Vec::new()),
            Some(cloud) => {
                cloud.update(&s.pos);
                let flat = |v: &[V3]| v.iter().flat_map(|p| p.map(|c| c as f32)).collect::<Vec<f32>>();
                (flat(&cloud.positions), nodes, flat(&cloud.normals))
            }
        };
        let s = self.sim.state();
        let mut reference_positions = Vec::new();
        if let Some(sh) = self.shadow.as_mut() {
            sh.reference_at(s.time, &mut reference_positions);
        }
        StateFrame {
            frame: self.frames,
            time: s.time,
            episode: self.episode,
            level: self.level,
            coefficient_version: self.coefficient_version,
            positions,
            simulation_positions,
            normals,
            reference_positions,
            stepped: SystemTime::now(),
            transition,
        }
    }

    /// Hand out a state and metrics when their time has come.
    fn publish(&mut self, now: Instant) {
        if self.held {
            self.next_publish = now + self.publish_every;
            self.next_metrics = now + self.metrics_every;
            return;
        }
        if now >= self.next_publish {
            self.next_publish = advance_deadline(self.next_publish, self.publish_every, now);
            let frame = Arc::new(self.snapshot(false));
            self.states.send_replace(Some(frame));
        }
        if now >= self.next_metrics {
            self.next_metrics = advance_deadline(self.next_metrics, self.metrics_every, now);
            let wall = now.saturating_duration_since(self.window_start).as_secs_f64();
            let report = self.last;
            let m = MetricsFrame {
                frame: self.frames,
                time: self.sim.state().time,
                level: self.level,
                method: self.method,
                predicted_error: self.predicted_error,
                live_error: self.live_error,
                step_cost_us: if self.window_steps > 0 {
                    self.window_busy.as_secs_f64() * 1e6 / self.window_steps as f64
                } else {
                    0.0
                },
                real_time_factor: if wall > 0.0 { self.window_sim / wall } else { 0.0 },
                overruns: self.overruns,
                lag_resets: self.lag_resets,
                divergences: self.divergences,
                rollbacks: self.rollbacks,
                halted: self.halted.clone(),
                kinetic_energy: report.map_or(0.0, |r| r.kinetic_energy),
                potential_energy: report.map_or(0.0, |r| r.elastic_energy + r.gravity_energy),
                max_strain: report.map_or(0.0, |r| r.max_strain_overall()),
                coefficient_version: self.coefficient_version,
                paused: self.paused,
                dt: self.dt(),
            };
            self.metrics.send_replace(Some(Arc::new(m)));
            self.window_start = now;
            self.window_sim = 0.0;
            self.window_steps = 0;
            self.window_busy = Duration::ZERO;
            lock(&self.status).frame = self.frames;
        }
    }
}

/// The next deadline after `now` on the grid `last + k·every` (a late
/// publisher skips the missed slots instead of bursting).
fn advance_deadline(last: Instant, every: Duration, now: Instant) -> Instant {
    let next = last + every;
    if next > now {
        next
    } else {
        now + every
    }
}

/// Simulated time between divergence checkpoints (s).
const CHECKPOINT_INTERVAL: f64 = 0.5;
/// Simulated time without a divergence after which divergences count from
/// zero again (s).
const CLEAN_INTERVAL: f64 = 5.0;
/// A strain (L/L0 − 1) beyond which a step counts as diverged.
const DIVERGED_STRAIN: f64 = 10.0;
/// Divergences within a clean interval before the instance is halted.
pub const MAX_CONSECUTIVE_DIVERGENCES: u32 = 3;

/// Longest a stepping thread sleeps before looking at its commands again.
const MAX_IDLE: Duration = Duration::from_millis(5);

fn worker(mut runners: Vec<Runner>, stop: Arc<AtomicBool>, _settings: EngineSettings) {
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        let mut wake = now + MAX_IDLE;
        for r in &mut runners {
            r.poll_commands();
            r.advance(now);
            r.publish(Instant::now());
            wake = wake.min(r.next_due()).min(r.next_publish).min(r.next_metrics);
        }
        let now = Instant::now();
        if wake > now {
            std::thread::park_timeout(wake - now);
        }
    }
}

/// Lock, ignoring poisoning: a status is plain data that every critical
/// section writes whole, so a panicking writer leaves no half-made value.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
