//! Handing out states and metrics at their rates, through `watch`
//! channels that keep only the newest (a slow publisher never blocks
//! stepping), and the status `info` replies describe.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use tokio::sync::{mpsc, watch};

use super::runner::Runner;
use super::{lock, AppliedInput, HandleParts, MetricsFrame, StateFrame, Status};
use crate::sim::vec3::V3;
use crate::sim::StepReport;

/// What the publishing stage keeps: the deadlines of states and metrics,
/// the metrics window, and the sending ends of everything that leaves the
/// engine.
pub(super) struct Publishing {
    next_publish: Instant,
    publish_every: Duration,
    next_metrics: Instant,
    metrics_every: Duration,
    // The metrics window: since the last metrics.
    window_start: Instant,
    window_sim: f64,
    window_steps: u64,
    window_busy: Duration,
    /// The report of the last full step, which the metrics show.
    pub(super) last: Option<StepReport>,
    states: watch::Sender<Option<Arc<StateFrame>>>,
    metrics: watch::Sender<Option<Arc<MetricsFrame>>>,
    transitions: mpsc::UnboundedSender<Arc<StateFrame>>,
    /// Every input that took effect, for the service to publish.
    applied: mpsc::UnboundedSender<AppliedInput>,
    status: Arc<Mutex<Status>>,
}

impl Publishing {
    /// States every `publish_every` and metrics every `metrics_every` from
    /// `now`; the receiving ends, for the instance `name`'s handle, with them.
    pub(super) fn new(
        name: String,
        status: Status,
        now: Instant,
        publish_every: Duration,
        metrics_every: Duration,
    ) -> (Publishing, HandleParts) {
        let (states_tx, states_rx) = watch::channel(None);
        let (metrics_tx, metrics_rx) = watch::channel(None);
        let (trans_tx, trans_rx) = mpsc::unbounded_channel();
        let (applied_tx, applied_rx) = mpsc::unbounded_channel();
        let status = Arc::new(Mutex::new(status));
        let publishing = Publishing {
            next_publish: now,
            publish_every,
            next_metrics: now,
            metrics_every,
            window_start: now,
            window_sim: 0.0,
            window_steps: 0,
            window_busy: Duration::ZERO,
            last: None,
            states: states_tx,
            metrics: metrics_tx,
            transitions: trans_tx,
            applied: applied_tx,
            status: status.clone(),
        };
        let parts = HandleParts {
            name,
            states: states_rx,
            metrics: metrics_rx,
            transitions: trans_rx,
            applied: applied_rx,
            status,
        };
        (publishing, parts)
    }

    pub(super) fn next_publish(&self) -> Instant {
        self.next_publish
    }

    pub(super) fn next_metrics(&self) -> Instant {
        self.next_metrics
    }

    /// A pass took `steps` steps, `sim` simulated seconds, in `busy`.
    pub(super) fn count_steps(&mut self, busy: Duration, steps: u64, sim: f64) {
        self.window_busy += busy;
        self.window_steps += steps;
        self.window_sim += sim;
    }

    /// The report the metrics show from now.
    pub(super) fn show(&mut self, report: StepReport) {
        self.last = Some(report);
    }

    /// An input that took effect.
    pub(super) fn applied(&self, input: AppliedInput) {
        // A closed receiver (no service, or it is stopping) wants none.
        let _ = self.applied.send(input);
    }

    /// The two states of a switch, in order, the second also as the newest.
    pub(super) fn transition(&self, before: StateFrame, after: StateFrame) {
        let _ = self.transitions.send(Arc::new(before));
        let after = Arc::new(after);
        let _ = self.transitions.send(after.clone());
        self.states.send_replace(Some(after));
    }

    /// The status, to update.
    pub(super) fn status(&self) -> MutexGuard<'_, Status> {
        lock(&self.status)
    }

    /// While held: nothing is due until `every` after `now`.
    fn hold(&mut self, now: Instant) {
        self.next_publish = now + self.publish_every;
        self.next_metrics = now + self.metrics_every;
    }

    /// True when a state is due at `now` (the next is then scheduled).
    fn state_due(&mut self, now: Instant) -> bool {
        let due = now >= self.next_publish;
        if due {
            self.next_publish = advance_deadline(self.next_publish, self.publish_every, now);
        }
        due
    }

    /// True when metrics are due at `now` (the next are then scheduled).
    fn metrics_due(&mut self, now: Instant) -> bool {
        let due = now >= self.next_metrics;
        if due {
            self.next_metrics = advance_deadline(self.next_metrics, self.metrics_every, now);
        }
        due
    }

    /// The window's mean step cost (µs) and real-time factor at `now`.
    fn window_rates(&self, now: Instant) -> (f64, f64) {
        let wall = now.saturating_duration_since(self.window_start).as_secs_f64();
        let step_cost_us = if self.window_steps > 0 {
            self.window_busy.as_secs_f64() * 1e6 / self.window_steps as f64
        } else {
            0.0
        };
        (step_cost_us, if wall > 0.0 { self.window_sim / wall } else { 0.0 })
    }

    /// Hand out `m`, the metrics at step `frame`, and start the next window at `now`.
    fn send_metrics(&mut self, m: MetricsFrame, now: Instant, frame: u64) {
        self.metrics.send_replace(Some(Arc::new(m)));
        self.window_start = now;
        self.window_sim = 0.0;
        self.window_steps = 0;
        self.window_busy = Duration::ZERO;
        lock(&self.status).frame = frame;
    }
}

impl Runner {
    pub(super) fn snapshot(&mut self, transition: bool) -> StateFrame {
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
        if !self.inputs.touched_episode() {
            self.live.reference_at(s.time, &mut reference_positions);
        }
        let collider_positions = self
            .sim
            .loads()
            .colliders
            .iter()
            .flat_map(|body| body.at(s.time).0.map(|c| c as f32))
            .collect();
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
            collider_positions,
            stepped: SystemTime::now(),
            transition,
        }
    }

    /// Hand out a state and metrics when their time has come.
    pub(super) fn publish(&mut self, now: Instant) {
        if self.pacing.held() {
            self.publishing.hold(now);
            return;
        }
        if self.publishing.state_due(now) {
            let frame = Arc::new(self.snapshot(false));
            self.publishing.states.send_replace(Some(frame));
        }
        if self.publishing.metrics_due(now) {
            let (step_cost_us, real_time_factor) = self.publishing.window_rates(now);
            let report = self.publishing.last;
            let (live_error, live_error_time) = self.live.error();
            let m = MetricsFrame {
                frame: self.frames,
                time: self.sim.state().time,
                level: self.level,
                method: self.method,
                predicted_error: self.predicted_error,
                live_error,
                live_error_time,
                step_cost_us,
                real_time_factor,
                overruns: self.pacing.overruns(),
                stalls: self.pacing.stalls(),
                lag_resets: self.pacing.lag_resets(),
                divergences: self.divergence.divergences(),
                rollbacks: self.divergence.rollbacks(),
                halted: self.divergence.halted().cloned(),
                kinetic_energy: report.map_or(0.0, |r| r.kinetic_energy),
                potential_energy: report.map_or(0.0, |r| r.elastic_energy + r.gravity_energy),
                max_strain: report.map_or(0.0, |r| r.max_strain_overall()),
                coefficient_version: self.coefficient_version,
                paused: self.pacing.paused(),
                dt: self.dt(),
                inputs: self.inputs.client_inputs(),
                touched: self.touched(),
            };
            self.publishing.send_metrics(m, now, self.frames);
        }
    }

    /// Bring what `info` replies describe up to date.
    pub(super) fn update_status(&self) {
        let mut s = self.publishing.status();
        s.level = self.level;
        s.method = self.method;
        s.material = self.material;
        s.dt = self.dt();
        s.coefficient_version = self.coefficient_version;
        s.predicted_error = self.predicted_error;
        s.paused = self.pacing.paused();
        s.halted = self.divergence.halted().cloned();
        if !Arc::ptr_eq(&s.topology, self.sim.topology()) {
            s.topology = self.sim.topology().clone();
            s.pinned = self.sim.loads().pins.iter().map(|p| p.node).collect();
            s.simulation_points = self.cloud.as_ref().map(|c| c.kept.clone());
        }
        s.frame = self.frames;
        s.o_max = self.live.o_max();
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
