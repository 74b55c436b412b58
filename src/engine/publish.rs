//! Handing out states and metrics at their rates, through `watch`
//! channels that keep only the newest (a slow publisher never blocks
//! stepping).

use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use super::runner::Runner;
use super::{lock, MetricsFrame, StateFrame};
use crate::sim::vec3::V3;

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
        if let Some(sh) = self.shadow.as_mut().filter(|_| !self.touched_episode) {
            sh.reference_at(s.time, &mut reference_positions);
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
                live_error_time: self.live_error_time,
                step_cost_us: if self.window_steps > 0 {
                    self.window_busy.as_secs_f64() * 1e6 / self.window_steps as f64
                } else {
                    0.0
                },
                real_time_factor: if wall > 0.0 { self.window_sim / wall } else { 0.0 },
                overruns: self.overruns,
                stalls: self.stalls,
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
                inputs: self.inputs,
                touched: self.touched(),
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
