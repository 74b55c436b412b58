//! The dynamic state of a cloth: a plain value that can be copied, recorded,
//! compared and transferred between resolutions.

use super::topology::Topology;

/// Positions and velocities of every node plus the clock.
///
/// Layout: structure of arrays. `pos` holds `[x_0 … x_{n−1}, y_0 … y_{n−1},
/// z_0 … z_{n−1}]` (metres); `vel` the same in m/s. This is what the force
/// kernel reads as contiguous slices.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    /// Node positions, SoA, length 3n.
    pub pos: Vec<f64>,
    /// Node velocities, SoA, length 3n.
    pub vel: Vec<f64>,
    /// Simulated time (s).
    pub time: f64,
    /// Steps taken since t = 0.
    pub step: u64,
}

impl State {
    /// The cloth at its rest shape, at rest, at t = 0.
    pub fn at_rest(topology: &Topology) -> State {
        let n = topology.n_nodes;
        let mut pos = vec![0.0; 3 * n];
        for (k, p) in topology.rest_positions.iter().enumerate() {
            for c in 0..3 {
                pos[c * n + k] = p[c];
            }
        }
        State {
            pos,
            vel: vec![0.0; 3 * n],
            time: 0.0,
            step: 0,
        }
    }

    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.pos.len() / 3
    }

    /// Position of node `k`.
    pub fn position(&self, k: usize) -> [f64; 3] {
        let n = self.n_nodes();
        [self.pos[k], self.pos[n + k], self.pos[2 * n + k]]
    }

    /// Velocity of node `k`.
    pub fn velocity(&self, k: usize) -> [f64; 3] {
        let n = self.n_nodes();
        [self.vel[k], self.vel[n + k], self.vel[2 * n + k]]
    }

    /// Set the position of node `k`.
    pub fn set_position(&mut self, k: usize, p: [f64; 3]) {
        let n = self.n_nodes();
        for (c, value) in p.into_iter().enumerate() {
            self.pos[c * n + k] = value;
        }
    }

    /// Set the velocity of node `k`.
    pub fn set_velocity(&mut self, k: usize, v: [f64; 3]) {
        let n = self.n_nodes();
        for (c, value) in v.into_iter().enumerate() {
            self.vel[c * n + k] = value;
        }
    }

    /// True when every position and velocity is finite.
    pub fn is_finite(&self) -> bool {
        // x·0 is 0 for finite x and NaN otherwise; lane-wise sums propagate
        // the NaN and vectorise.
        let zero_sum = |v: &[f64]| {
            let (chunks, tail) = v.as_chunks::<8>();
            let mut acc = [0.0; 8];
            for c in chunks {
                for j in 0..8 {
                    acc[j] += c[j] * 0.0;
                }
            }
            acc.iter().sum::<f64>() + tail.iter().map(|x| x * 0.0).sum::<f64>()
        };
        zero_sum(&self.pos) == 0.0 && zero_sum(&self.vel) == 0.0
    }

    /// Largest distance of any node from where it is in `other` (same size).
    pub fn max_distance(&self, other: &State) -> f64 {
        let n = self.n_nodes();
        (0..n)
            .map(|k| {
                let (a, b) = (self.position(k), other.position(k));
                ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
            })
            .fold(0.0, f64::max)
    }
}
