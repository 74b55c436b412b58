//! The displacement error of Sung 2018 eq. 9, accumulated frame by frame.
//!
//! For coarse node i at frame t: `e_i(t) = |p_ref,i(t) − p_sim,i(t)| / O_max`,
//! with `p_ref,i` the barycentrically mapped reference position and `O_max` the
//! largest distance of any reference node from its rest position over the
//! run. Pinned nodes are included (their error is ~0, as in the paper, which
//! averages over all coherent nodes).
//!
//! The 95th percentile comes from a histogram of 0.01 %-wide bins up to 200 %
//! (values beyond fall in an overflow bin and are reported as the maximum),
//! so memory does not grow with the run length.

/// Histogram bin width (fraction of O_max).
const BIN: f64 = 1e-4;
/// Bins up to 200 % error.
const BINS: usize = 20_000;

/// Error statistics of one coarse run against the reference.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorReport {
    /// Frames scored.
    pub frames: usize,
    /// Mean over nodes and frames (fraction of O_max; ×100 for %).
    pub mean: f64,
    /// 95th percentile over nodes and frames (histogram resolution 1e-4).
    pub p95: f64,
    /// Largest single node error.
    pub max: f64,
    /// Frame (0-based among the scored frames) with the largest mean error.
    pub worst_frame: usize,
    /// Simulated time of that frame (s).
    pub worst_time: f64,
    /// Mean error of that frame.
    pub worst_frame_mean: f64,
    /// Mean over the first quarter of the scored frames.
    pub first_quarter: f64,
    /// Mean over the last quarter of the scored frames.
    pub last_quarter: f64,
    /// Per-node mean error over all frames.
    pub node_mean: Vec<f64>,
    /// Per-node error at the worst frame.
    pub worst_frame_nodes: Vec<f64>,
    /// Mean error of every scored frame, in order.
    pub frame_means: Vec<f64>,
    /// Coarse positions at the worst frame (SoA), for error maps.
    pub worst_positions: Vec<f64>,
    /// True when the coarse run diverged (non-finite state): every statistic
    /// is then +∞.
    pub diverged: bool,
}

impl ErrorReport {
    /// Mean error over scored frames `range` (indices into [`ErrorReport::frame_means`];
    /// every frame has the same node count, so this is the node-and-frame mean).
    pub fn mean_over(&self, range: std::ops::Range<usize>) -> f64 {
        if self.diverged {
            return f64::INFINITY;
        }
        let s = &self.frame_means[range.start.min(self.frame_means.len())..range.end.min(self.frame_means.len())];
        if s.is_empty() {
            f64::NAN
        } else {
            s.iter().sum::<f64>() / s.len() as f64
        }
    }

    /// The report of a run that diverged.
    pub fn diverged(n_nodes: usize) -> ErrorReport {
        ErrorReport {
            frames: 0,
            mean: f64::INFINITY,
            p95: f64::INFINITY,
            max: f64::INFINITY,
            worst_frame: 0,
            worst_time: f64::NAN,
            worst_frame_mean: f64::INFINITY,
            first_quarter: f64::INFINITY,
            last_quarter: f64::INFINITY,
            node_mean: vec![f64::INFINITY; n_nodes],
            worst_frame_nodes: vec![f64::INFINITY; n_nodes],
            worst_positions: Vec::new(),
            frame_means: Vec::new(),
            diverged: true,
        }
    }
}

/// Streaming accumulator of [`ErrorReport`]. Allocates once.
#[derive(Debug, Clone)]
pub struct ErrorAccumulator {
    inv_o_max: f64,
    n: usize,
    frames_expected: usize,
    frame_means: Vec<f64>,
    frame_times: Vec<f64>,
    node_sum: Vec<f64>,
    current: Vec<f64>,
    worst: Vec<f64>,
    worst_positions: Vec<f64>,
    worst_mean: f64,
    histogram: Vec<u64>,
    max: f64,
    sum: f64,
    diverged: bool,
}

impl ErrorAccumulator {
    /// Accumulator for `n_nodes` coarse nodes over about `frames` frames.
    ///
    /// # Panics
    /// When `o_max` is not positive and finite (a reference that never moved
    /// has no meaningful relative error).
    pub fn new(o_max: f64, n_nodes: usize, frames: usize) -> ErrorAccumulator {
        assert!(o_max.is_finite() && o_max > 0.0, "O_max must be positive, got {o_max}");
        ErrorAccumulator {
            inv_o_max: 1.0 / o_max,
            n: n_nodes,
            frames_expected: frames,
            frame_means: Vec::with_capacity(frames),
            frame_times: Vec::with_capacity(frames),
            node_sum: vec![0.0; n_nodes],
            current: vec![0.0; n_nodes],
            worst: vec![0.0; n_nodes],
            worst_positions: vec![0.0; 3 * n_nodes],
            worst_mean: -1.0,
            histogram: vec![0; BINS + 1],
            max: 0.0,
            sum: 0.0,
            diverged: false,
        }
    }

    /// Score one frame: `reference` the mapped reference positions and
    /// `sim` the coarse positions, both SoA of n coarse nodes.
    pub fn push(&mut self, time: f64, reference: &[f64], sim: &[f64]) {
        let n = self.n;
        assert!(reference.len() == 3 * n && sim.len() == 3 * n, "field sizes");
        let mut frame_sum = 0.0;
        for k in 0..n {
            let dx = reference[k] - sim[k];
            let dy = reference[n + k] - sim[n + k];
            let dz = reference[2 * n + k] - sim[2 * n + k];
            let e = (dx * dx + dy * dy + dz * dz).sqrt() * self.inv_o_max;
            if !e.is_finite() {
                self.diverged = true;
                return;
            }
            self.current[k] = e;
            self.node_sum[k] += e;
            frame_sum += e;
            self.max = self.max.max(e);
            let bin = ((e / BIN) as usize).min(BINS);
            self.histogram[bin] += 1;
        }
        self.sum += frame_sum;
        let mean = frame_sum / n as f64;
        if mean > self.worst_mean {
            self.worst_mean = mean;
            self.worst.copy_from_slice(&self.current);
            self.worst_positions.copy_from_slice(sim);
        }
        self.frame_means.push(mean);
        self.frame_times.push(time);
    }

    /// Mark the run as diverged (the coarse simulation produced non-finite values).
    pub fn mark_diverged(&mut self) {
        self.diverged = true;
    }

    /// Frames scored so far.
    pub fn frames(&self) -> usize {
        self.frame_means.len()
    }

    /// Frames this accumulator was sized for.
    pub fn frames_expected(&self) -> usize {
        self.frames_expected
    }

    /// Running mean error (∞ after a divergence, 0 before any frame).
    pub fn mean(&self) -> f64 {
        if self.diverged {
            f64::INFINITY
        } else if self.frame_means.is_empty() {
            0.0
        } else {
            self.sum / (self.n * self.frame_means.len()) as f64
        }
    }

    /// The statistics so far.
    pub fn report(&self) -> ErrorReport {
        let frames = self.frame_means.len();
        if self.diverged || frames == 0 {
            let mut r = ErrorReport::diverged(self.n);
            r.diverged = self.diverged;
            if !self.diverged {
                r = ErrorReport {
                    mean: 0.0,
                    p95: 0.0,
                    max: 0.0,
                    worst_frame_mean: 0.0,
                    first_quarter: 0.0,
                    last_quarter: 0.0,
                    node_mean: vec![0.0; self.n],
                    worst_frame_nodes: vec![0.0; self.n],
                    ..r
                };
            }
            return r;
        }
        let total = (self.n * frames) as u64;
        let rank = (0.95 * total as f64).ceil() as u64;
        let mut seen = 0;
        let mut p95 = self.max;
        for (b, &count) in self.histogram.iter().enumerate() {
            seen += count;
            if seen >= rank {
                p95 = if b == BINS {
                    self.max
                } else {
                    ((b as f64 + 1.0) * BIN).min(self.max)
                };
                break;
            }
        }
        let quarter = (frames / 4).max(1);
        let avg = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
        let worst_frame = self
            .frame_means
            .iter()
            .enumerate()
            .fold(0, |w, (i, &m)| if m > self.frame_means[w] { i } else { w });
        ErrorReport {
            frames,
            mean: self.sum / total as f64,
            p95,
            max: self.max,
            worst_frame,
            worst_time: self.frame_times[worst_frame],
            worst_frame_mean: self.frame_means[worst_frame],
            first_quarter: avg(&self.frame_means[..quarter]),
            last_quarter: avg(&self.frame_means[frames - quarter..]),
            node_mean: self.node_sum.iter().map(|s| s / frames as f64).collect(),
            worst_frame_nodes: self.worst.clone(),
            worst_positions: self.worst_positions.clone(),
            frame_means: self.frame_means.clone(),
            diverged: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_runs_score_exactly_zero() {
        let mut acc = ErrorAccumulator::new(0.5, 3, 4);
        let p = [0.1, 0.2, 0.3, 1.0, 2.0, 3.0, -1.0, 0.0, 1.0];
        for f in 0..4 {
            acc.push(f as f64, &p, &p);
        }
        let r = acc.report();
        assert_eq!((r.mean, r.p95, r.max), (0.0, 0.0, 0.0));
        assert!(r.node_mean.iter().all(|&e| e == 0.0));
    }

    #[test]
    fn matches_a_hand_computation_on_two_nodes() {
        // Two nodes, O_max = 2. Frame 0: node 0 off by (3,4,0) → 5/2 = 2.5,
        // node 1 exact. Frame 1: node 0 exact, node 1 off by (0,0,1) → 0.5.
        let mut acc = ErrorAccumulator::new(2.0, 2, 2);
        let zero = [0.0; 6];
        acc.push(0.0, &[3.0, 0.0, 4.0, 0.0, 0.0, 0.0], &zero);
        acc.push(0.1, &[0.0, 0.0, 0.0, 0.0, 0.0, 1.0], &zero);
        let r = acc.report();
        assert!((r.mean - (2.5 + 0.5) / 4.0).abs() < 1e-15);
        assert_eq!(r.max, 2.5);
        assert_eq!(r.worst_frame, 0);
        assert_eq!(r.worst_frame_nodes, vec![2.5, 0.0]);
        assert_eq!(r.node_mean, vec![1.25, 0.25]);
        assert!((r.first_quarter - 1.25).abs() < 1e-15 && (r.last_quarter - 0.25).abs() < 1e-15);
        assert!((r.mean_over(1..2) - 0.25).abs() < 1e-15 && (r.mean_over(0..2) - r.mean).abs() < 1e-15);
        // 4 values {2.5, 0, 0, 0.5}: the 95th percentile (rank 4) is the largest.
        assert_eq!(r.p95, 2.5);
    }

    #[test]
    fn non_finite_positions_mark_the_run_diverged() {
        let mut acc = ErrorAccumulator::new(1.0, 1, 1);
        acc.push(0.0, &[0.0; 3], &[f64::NAN, 0.0, 0.0]);
        let r = acc.report();
        assert!(r.diverged && r.mean.is_infinite());
    }
}
