//! The reference replayed beside a running level: the live error.

use std::sync::Arc;

use crate::plan::{Basis, Prepared};
use crate::points::cloud::CloudMap;
use crate::points::estimate::SurfaceReference;
use crate::sim::vec3::{dist, V3};

/// Compares a running level with its recorded reference once per reference
/// frame interval (frame f of a recording is at time (f + 1)·interval for
/// surfaces; cloth recordings carry their frame times).
pub(super) struct Shadow {
    prepared: Arc<Prepared>,
    /// Reference frame interval (s).
    interval: f64,
    /// The last interval compared.
    last_slot: i64,
    /// Cloth: the reference mapped onto the level's nodes at the two frames
    /// around the comparison time.
    mapped: Vec<f64>,
    mapped_next: Vec<f64>,
}

impl Shadow {
    pub(super) fn new(prepared: Arc<Prepared>, n_nodes: usize) -> Shadow {
        let (interval, n) = match &prepared.basis {
            Basis::Cloth(problem) => (
                problem.reference.dt * problem.reference.spec.metric_stride as f64,
                n_nodes,
            ),
            Basis::Surface { reference, .. } => (reference.interval, 0),
        };
        Shadow {
            prepared,
            interval,
            last_slot: -1,
            mapped: vec![0.0; 3 * n],
            mapped_next: vec![0.0; 3 * n],
        }
    }

    /// The cloth level's problem (its reference and correlation); `None`
    /// for a surface.
    pub(super) fn problem(&self) -> Option<&Arc<crate::estimate::LodProblem>> {
        match &self.prepared.basis {
            Basis::Cloth(problem) => Some(problem),
            Basis::Surface { .. } => None,
        }
    }

    /// True once per reference frame interval.
    pub(super) fn due(&mut self, t: f64) -> bool {
        let slot = (t / self.interval).floor() as i64;
        let due = slot != self.last_slot;
        self.last_slot = slot;
        due
    }

    /// Cloth: map the reference frames around `t` onto the level's nodes
    /// (`mapped`, `mapped_next`) and return the weight of the later one.
    fn map_cloth(&mut self, t: f64) -> Option<f64> {
        let Basis::Cloth(problem) = &self.prepared.basis else {
            return None;
        };
        let reference = &problem.reference;
        let (a, b, w) = bracket(&reference.frame_times, t)?;
        let correlation = problem.correlation();
        correlation.map(&reference.frames[a], &mut self.mapped);
        correlation.map(&reference.frames[b], &mut self.mapped_next);
        Some(w)
    }

    /// Mean relative distance of the level at `pos` (SoA; a surface moves
    /// its `cloud` there and is compared on every cloud point) from the
    /// reference at time `t`, interpolated linearly between its frames;
    /// None outside the recording.
    pub(super) fn error_at(&mut self, t: f64, pos: &[f64], cloud: Option<&mut CloudMap>) -> Option<f64> {
        match cloud {
            None => {
                let w = self.map_cloth(t)?;
                let o_max = match &self.prepared.basis {
                    Basis::Cloth(problem) => problem.reference.o_max,
                    Basis::Surface { .. } => return None,
                };
                let n = pos.len() / 3;
                let mut sum = 0.0;
                for k in 0..n {
                    let d2 = (0..3)
                        .map(|c| {
                            let r = (1.0 - w) * self.mapped[c * n + k] + w * self.mapped_next[c * n + k];
                            (r - pos[c * n + k]).powi(2)
                        })
                        .sum::<f64>();
                    sum += d2.sqrt();
                }
                Some(sum / n as f64 / o_max)
            }
            Some(cloud) => {
                let Basis::Surface { reference, .. } = &self.prepared.basis else {
                    return None;
                };
                let (ra, rb, w) = surface_frames(reference, t)?;
                cloud.update(pos);
                let mut sum = 0.0;
                for (i, p) in cloud.positions.iter().enumerate() {
                    let r = [0, 1, 2].map(|c| (1.0 - w) * ra[i][c] + w * rb[i][c]);
                    sum += dist(*p, r);
                }
                Some(sum / cloud.positions.len() as f64 / reference.o_max)
            }
        }
    }

    /// The reference at time `t` into `out`, interleaved x, y, z like a
    /// published state (cloth: on the level's nodes; surface: every cloud
    /// point); left empty outside the recording.
    pub(super) fn reference_at(&mut self, t: f64, out: &mut Vec<f32>) {
        out.clear();
        if matches!(self.prepared.basis, Basis::Cloth(_)) {
            let Some(w) = self.map_cloth(t) else {
                return;
            };
            let n = self.mapped.len() / 3;
            out.reserve(3 * n);
            for k in 0..n {
                for c in 0..3 {
                    out.push(((1.0 - w) * self.mapped[c * n + k] + w * self.mapped_next[c * n + k]) as f32);
                }
            }
        } else if let Basis::Surface { reference, .. } = &self.prepared.basis {
            let Some((ra, rb, w)) = surface_frames(reference, t) else {
                return;
            };
            out.reserve(3 * ra.len());
            for (a, b) in ra.iter().zip(rb) {
                out.extend((0..3).map(|c| ((1.0 - w) * a[c] + w * b[c]) as f32));
            }
        }
    }
}

/// The recorded cloud frames around `t` and the weight of the later one;
/// frame f is at (f + 1)·interval, so the frame count is searched, not a
/// time list.
fn surface_frames(reference: &SurfaceReference, t: f64) -> Option<(&[V3], &[V3], f64)> {
    let f = t / reference.interval - 1.0;
    if !(f >= 0.0) || f >= reference.frames.len().saturating_sub(1) as f64 {
        return None;
    }
    let a = f.floor() as usize;
    Some((&reference.frames[a], &reference.frames[a + 1], f - a as f64))
}

/// The frames around `t` in `times` and the weight of the later one.
fn bracket(times: &[f64], t: f64) -> Option<(usize, usize, f64)> {
    let i = times.partition_point(|&ft| ft <= t);
    if i == 0 || i >= times.len() {
        return None;
    }
    let (a, b) = (i - 1, i);
    Some((a, b, ((t - times[a]) / (times[b] - times[a])).clamp(0.0, 1.0)))
}
