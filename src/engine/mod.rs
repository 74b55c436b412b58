//! The stepping engine: the only code that knows threads and the wall clock.
//!
//! Instances are spread over a fixed set of OS threads (one per core by
//! default; never tokio workers). Each thread runs its instances at their
//! fixed dt, paced to the wall clock: simulated time tracks real time; an
//! instance that runs late catches up at most `max_catch_up` seconds of
//! simulated time per pass (counting an overrun when that is not enough)
//! and, beyond `max_lag` behind, drops the backlog (a lag reset). dt is
//! never stretched. A thread that wakes far later than it asked to (the
//! machine or the OS did not run it) counts a stall for its instances.
//!
//! A cloth large enough to split its step (`sim::SPLIT_MIN_NODES`) borrows
//! a second core for it: stepping threads come in pairs, each serving the
//! other's [`Lender`] whenever it is idle (between its own steps), and a
//! lone stepping thread gets a helper thread that does nothing else. A
//! half nobody picked up is run by the stepping thread itself, so a busy
//! partner never delays a step; the result does not depend on who ran it.
//!
//! Commands (switch, pause, reset) arrive on a channel and are applied
//! between steps. States and metrics leave through `watch` channels that
//! hold only the newest value, so a slow publisher drops frames and never
//! blocks stepping. The two states at a level switch (old level, new level,
//! same instant) also go through a small unbounded channel so that both
//! reach the bus.

mod apply;
mod command;
mod divergence;
mod error;
mod frame;
mod input;
mod live;
mod publish;
mod replica;
mod runner;
mod shadow;
mod switch;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tokio::sync::watch;

use crate::estimate::Method;
use crate::plan::Level;
use crate::points::cloud::CloudMap;
use crate::sim::{Lender, Simulation};
use crate::touch::Touch;
use runner::Runner;

pub use command::Command;
pub use divergence::MAX_CONSECUTIVE_DIVERGENCES;
pub use error::{RestoreError, Stopped, SwitchError};
pub use frame::{
    AppliedInput, Coefficients, ControlOutcome, InputOutcome, MetricsFrame, Snapshot, StateFrame, Status, SwitchOutcome,
};

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
    /// Live input on a grid cloth (`None` for a surface: inputs refused).
    pub touch: Option<Touch>,
    /// Seconds without an input after which the instance lets go of
    /// everything and returns to its scene's script.
    pub input_idle: f64,
    /// A switch to a coarser cloth level settles the carried shape by one
    /// backward-Euler step of this many seconds ([`crate::lod::settle`]).
    pub switch_settle: Option<f64>,
}

impl InstanceSetup {
    /// `sim` stepping at `level` with the scene's coefficients (`same`),
    /// for as long as the process runs: no reference beside it (no shadow,
    /// no looping), no input, 30 states a second, released after 10 s
    /// without input (the config's `[input] idle`). What differs from
    /// this is set with struct update syntax:
    /// `InstanceSetup { publish_hz: 60.0, ..InstanceSetup::new(…) }`.
    pub fn new(name: impl Into<String>, sim: Simulation, level: Level) -> InstanceSetup {
        InstanceSetup {
            name: name.into(),
            sim,
            cloud: None,
            level,
            method: Method::Same,
            publish_hz: 30.0,
            duration: f64::INFINITY,
            looping: false,
            shadow: false,
            hold: false,
            touch: None,
            input_idle: 10.0,
            switch_settle: None,
        }
    }
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
    /// Every input that took effect, in order (none is dropped; the
    /// service's rate limit bounds how fast they come).
    pub applied: Arc<tokio::sync::Mutex<tokio::sync::mpsc::UnboundedReceiver<AppliedInput>>>,
    status: Arc<Mutex<Status>>,
}

impl InstanceHandle {
    /// Queue a command and wake the instance's thread. Err when the engine
    /// has stopped.
    pub fn send(&self, command: Command) -> Result<(), Stopped> {
        self.commands.send(command).map_err(|_| Stopped)?;
        self.thread.unpark();
        Ok(())
    }

    pub fn status(&self) -> Status {
        lock(&self.status).clone()
    }

    /// The stepping thread this instance runs on.
    pub fn stepping_thread(&self) -> std::thread::ThreadId {
        self.thread.id()
    }
}

/// How the engine paces its instances (validated from the config's
/// `[engine]` section by the service).
#[derive(Debug, Clone, Copy)]
pub struct EngineSettings {
    /// Stepping threads (at most one per instance is used).
    pub threads: usize,
    /// Simulated seconds an instance may catch up in one pass of its
    /// thread; a pass that is further behind counts an overrun. In time,
    /// not steps: a bound in steps made an instance with a small dt (a
    /// 64-step pass is 18 ms of the hanging scene, 102 ms of the sphere's)
    /// overrun at every stall of the machine longer than that.
    pub max_catch_up: f64,
    /// Seconds an instance may fall behind the wall clock before its
    /// backlog is dropped (a lag reset).
    pub max_lag: f64,
    /// Longest an instance steps in one pass of its thread before the
    /// others there get their turn (the step under way is finished; what is
    /// left stays due for its next pass). [`PASS_SLICE`] in the daemon.
    pub slice: Duration,
    /// Metrics published per second per instance.
    pub metrics_hz: f64,
    /// Called first on the thread of a touched episode's reference replay,
    /// to put it below stepping but above background preparation: the
    /// touching client watches the live error it gives (the service's
    /// `client_priority`).
    pub replay_class: fn(),
}

/// The running engine.
pub struct Engine {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    handles: Vec<InstanceHandle>,
}

impl Engine {
    /// Start stepping `instances`, spread over `settings.threads` threads by
    /// their cost, measured ([`measured_cost`]).
    pub fn start(instances: Vec<InstanceSetup>, settings: EngineSettings) -> std::io::Result<Engine> {
        let stop = Arc::new(AtomicBool::new(false));
        let n_threads = settings.threads.clamp(1, instances.len().max(1));
        let mut buckets: Vec<(f64, Vec<Runner>)> = (0..n_threads).map(|_| (0.0, Vec::new())).collect();
        // Heaviest first onto the least loaded thread; handles come back in
        // the caller's order.
        let mut order: Vec<(usize, f64, InstanceSetup)> = instances
            .into_iter()
            .enumerate()
            .map(|(i, s)| (i, measured_cost(&s.sim), s))
            .collect();
        order.sort_by(|a, b| b.1.total_cmp(&a.1));
        let mut receivers = Vec::new();
        let mut pending = Vec::new();
        let mut names: Vec<Vec<String>> = vec![Vec::new(); n_threads];
        for (index, c, setup) in order {
            let (tx, rx) = mpsc::channel();
            let (runner, handle_parts) = Runner::new(setup, rx, settings);
            let b = (0..n_threads)
                .min_by(|&i, &j| buckets[i].0.total_cmp(&buckets[j].0))
                .unwrap_or(0);
            buckets[b].0 += c;
            names[b].push(format!("{} ({c:.2})", runner.name));
            buckets[b].1.push(runner);
            receivers.push(b);
            pending.push((index, tx, handle_parts));
        }
        for (i, ((load, _), names)) in buckets.iter().zip(&names).enumerate() {
            tracing::info!(
                thread = i,
                load = format!("{load:.2}"),
                instances = names.join(", "),
                "stepping thread: cores of stepping per second, measured"
            );
            if *load > LOAD_WARNING {
                tracing::warn!(
                    thread = i,
                    "the instances of stepping thread {i} need {load:.2} of a core to keep real time (measured at start): \
                     they will fall behind; run fewer or coarser instances, or on more cores"
                );
            }
        }
        // Thread i posts halves to lenders[i]; its partner (i ^ 1, or a
        // helper when it has none) serves them.
        let lenders: Vec<Arc<Lender>> = (0..n_threads).map(|_| Arc::new(Lender::new())).collect();
        let mut threads = Vec::new();
        for (i, (_, runners)) in buckets.into_iter().enumerate() {
            let stop = stop.clone();
            let own = lenders[i].clone();
            let serves = lenders.get(i ^ 1).cloned();
            let h = std::thread::Builder::new()
                .name(format!("lodcloth-step-{i}"))
                .spawn(move || worker(runners, stop, settings, own, serves))?;
            threads.push(h);
        }
        let mut helpers = Vec::new();
        if settings.threads >= 2 && n_threads % 2 == 1 {
            // The last stepping thread has no partner: a helper of its own.
            let lender = lenders[n_threads - 1].clone();
            let stop = stop.clone();
            let h = std::thread::Builder::new()
                .name(format!("lodcloth-help-{}", n_threads - 1))
                .spawn(move || helper(lender, stop))?;
            helpers.push(h);
        }
        for (i, lender) in lenders.iter().enumerate() {
            match (threads.get(i ^ 1), n_threads % 2 == 1 && i == n_threads - 1) {
                (Some(partner), false) => lender.set_helper(partner.thread().clone()),
                (_, true) => {
                    if let Some(h) = helpers.first() {
                        lender.set_helper(h.thread().clone());
                    }
                }
                (None, false) => {}
            }
        }
        threads.extend(helpers);
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
                        applied: Arc::new(tokio::sync::Mutex::new(parts.applied)),
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
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let threads = std::mem::take(&mut self.threads);
        for t in &threads {
            t.thread().unpark();
        }
        for t in threads {
            if t.join().is_err() {
                tracing::error!("a stepping thread panicked");
            }
        }
    }
}

impl Drop for Engine {
    /// An engine dropped without [`Engine::stop`] (the task that owned it
    /// was cancelled, its owner panicked) still stops its threads, without
    /// waiting for them: they finish the step they are in and exit, and
    /// never keep stepping for nobody.
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        for t in &self.threads {
            t.thread().unpark();
        }
    }
}

/// Above this share of a core, a stepping thread's instances are warned
/// about at start: the rest is what publishing, the live error and the
/// operating system need.
const LOAD_WARNING: f64 = 0.9;

/// Seconds of one core per simulated second of `sim`: a copy stepped for
/// about 3 ms in batches of about 0.5 ms (at least 2 steps each; the
/// first two steps not counted), the fastest batch's steps taken, so that
/// a batch the thread was preempted in does not count. Measured
/// rather than modelled: a count of nodes weighted by integrator put a
/// 915-vertex mesh cloth in RK4 (0.85 of a core by this measure on a
/// Zen 3 EPYC; 514 µs a step in the daemon, 0.96 of a core) beside two
/// grids on one thread, which then needed 1.05 cores while the other
/// used 0.34 (the default config on 2 cores: 1,045 overruns and 52 lag
/// resets in 45 s).
fn measured_cost(sim: &Simulation) -> f64 {
    let mut sim = sim.clone();
    sim.step();
    sim.step();
    let started = Instant::now();
    let mut fastest = f64::INFINITY;
    let mut batches = 0;
    while batches < 2 || (started.elapsed() < Duration::from_millis(3) && batches < 1000) {
        let batch = Instant::now();
        let mut steps = 0u32;
        while steps < 2 || (batch.elapsed() < Duration::from_micros(500) && steps < 10_000) {
            sim.step();
            steps += 1;
        }
        fastest = fastest.min(batch.elapsed().as_secs_f64() / f64::from(steps));
        batches += 1;
    }
    fastest / sim.params().dt
}

/// The receiving ends a [`Runner`] hands back for its [`InstanceHandle`].
struct HandleParts {
    name: String,
    states: watch::Receiver<Option<Arc<StateFrame>>>,
    metrics: watch::Receiver<Option<Arc<MetricsFrame>>>,
    transitions: tokio::sync::mpsc::UnboundedReceiver<Arc<StateFrame>>,
    applied: tokio::sync::mpsc::UnboundedReceiver<AppliedInput>,
    status: Arc<Mutex<Status>>,
}

/// The daemon's [`EngineSettings::slice`]. Without it, an instance that
/// needs more than its thread for a while (paper-2 with self-contact while
/// it folds: 0.6–0.9 ms a step at a dt of 0.73 ms) catches up 0.1 s of
/// simulated time in one pass, 50–110 ms of wall time, and every instance
/// on its thread waits that long and overruns with it. With it, that
/// instance falls behind alone.
pub const PASS_SLICE: Duration = Duration::from_millis(10);

/// An instance's pass (its commands, steps and publishing) longer than this
/// is logged by part: every other instance on the thread waited for it.
const SLOW_PASS: Duration = Duration::from_millis(50);

/// Longest a stepping thread sleeps before looking at its commands again.
const MAX_IDLE: Duration = Duration::from_millis(5);

/// A stepping thread that wakes this much later than it asked to was not
/// run (the machine, the hypervisor or the OS kept it off both cores): a
/// stall, counted for each of its instances. Waking costs tens of µs, and
/// a partner's half it ran meanwhile at most a few ms.
pub const STALL: Duration = Duration::from_millis(10);

fn worker(
    mut runners: Vec<Runner>,
    stop: Arc<AtomicBool>,
    _settings: EngineSettings,
    own: Arc<Lender>,
    serves: Option<Arc<Lender>>,
) {
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        let mut wake = now + MAX_IDLE;
        for r in &mut runners {
            let t = Instant::now();
            r.poll_commands();
            let commands = t.elapsed();
            let steps = r.advance(now, &*own);
            let stepping = t.elapsed() - commands;
            r.publish(Instant::now());
            let took = t.elapsed();
            if took > SLOW_PASS {
                tracing::warn!(
                    instance = %r.name,
                    ms = format!("{:.1}", took.as_secs_f64() * 1e3),
                    commands_ms = format!("{:.1}", commands.as_secs_f64() * 1e3),
                    stepping_ms = format!("{:.1}", stepping.as_secs_f64() * 1e3),
                    steps,
                    "one instance's pass held its stepping thread: every instance there waited"
                );
            }
            wake = wake
                .min(r.next_due())
                .min(r.publishing.next_publish())
                .min(r.publishing.next_metrics());
        }
        let asked = wake.max(Instant::now());
        match &serves {
            // Idle until `wake`: lend this core to the partner's halves
            // (its join unparks this thread).
            Some(partner) => serve_until(partner, wake),
            None => {
                let now = Instant::now();
                if wake > now {
                    std::thread::park_timeout(wake - now);
                }
            }
        }
        if Instant::now().saturating_duration_since(asked) > STALL {
            for r in &mut runners {
                r.pacing.stalled();
            }
        }
    }
}

/// How long a thread that just ran a half keeps watching for the next one
/// before it parks: the halves of one step follow each other within
/// microseconds (or after the longer of two halves), and waking a parked
/// thread costs tens of them.
const LINGER: Duration = Duration::from_micros(200);

/// Run `lender`'s halves until `until`, parking while none is posted.
fn serve_until(lender: &Lender, until: Instant) {
    loop {
        if lender.help_lingering(LINGER, until) > 0 {
            continue;
        }
        let now = Instant::now();
        if now >= until {
            return;
        }
        std::thread::park_timeout(until - now);
        if !lender.posted() {
            // Woken for its own work (a command, the stop) or timed out.
            return;
        }
    }
}

/// A thread that only serves `lender` (the partner of a lone stepping thread).
fn helper(lender: Arc<Lender>, stop: Arc<AtomicBool>) {
    while !stop.load(Ordering::Relaxed) {
        serve_until(&lender, Instant::now() + MAX_IDLE);
    }
}

/// Lock, ignoring poisoning: a status is plain data that every critical
/// section writes whole, so a panicking writer leaves no half-made value.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
