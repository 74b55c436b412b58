//! Provot-style strain limiting (position and velocity correction), Jacobi
//! flavour: every sweep computes all corrections from the same positions and
//! applies their per-node average, so the result is independent of spring
//! order and symmetric scenes stay symmetric.

use super::params::StrainLimit;
use super::topology::Topology;

/// Buffers of the limiter, sized once.
#[derive(Debug, Clone)]
pub(crate) struct StrainWorkspace {
    corr: Vec<f64>,
    count: Vec<f64>,
}

impl StrainWorkspace {
    pub(crate) fn new(topology: &Topology) -> StrainWorkspace {
        StrainWorkspace {
            corr: vec![0.0; 3 * topology.n_nodes],
            count: vec![0.0; topology.n_nodes],
        }
    }
}

/// Outcome of one limiting pass.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StrainOutcome {
    /// Sweeps that found a violation and corrected it.
    pub iterations: u32,
    /// Largest strain of a limited spring after the last sweep.
    pub max_strain: f64,
}

/// Shorten every limited spring longer than `(1 + max_strain)·L0` back to that
/// length. Each end moves in proportion to its inverse mass (pins have 0 and
/// never move); the same displacement divided by `dt` is added to the node's
/// velocity, which removes the stretching velocity that caused the overshoot.
pub(crate) fn limit(
    topology: &Topology,
    inv_mass: &[f64],
    limit: &StrainLimit,
    dt: f64,
    pos: &mut [f64],
    vel: &mut [f64],
    ws: &mut StrainWorkspace,
) -> StrainOutcome {
    let n = topology.n_nodes;
    let accept = 1.0 + limit.max_strain * (1.0 + limit.tolerance);
    let target = 1.0 + limit.max_strain;
    let mut outcome = StrainOutcome::default();
    for sweep in 0..=limit.max_iterations {
        ws.corr.fill(0.0);
        ws.count.fill(0.0);
        let mut worst: f64 = f64::NEG_INFINITY;
        let mut violated = false;
        for g in topology.groups.iter().filter(|g| limit.kinds[g.kind.index()]) {
            for s in 0..g.len() {
                let (a, b) = (g.a[s] as usize, g.b[s] as usize);
                let d = [pos[b] - pos[a], pos[n + b] - pos[n + a], pos[2 * n + b] - pos[2 * n + a]];
                let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let ratio = l * g.inv_rest[s];
                worst = worst.max(ratio);
                if ratio <= accept {
                    continue;
                }
                let (wa, wb) = (inv_mass[a], inv_mass[b]);
                let wsum = wa + wb;
                if wsum == 0.0 {
                    continue;
                }
                violated = true;
                // Move a towards b and b towards a by the excess, split by inverse mass.
                let excess = l - target * g.rest[s];
                let scale = excess / (l * wsum);
                for c in 0..3 {
                    ws.corr[c * n + a] += wa * scale * d[c];
                    ws.corr[c * n + b] -= wb * scale * d[c];
                }
                if wa > 0.0 {
                    ws.count[a] += 1.0;
                }
                if wb > 0.0 {
                    ws.count[b] += 1.0;
                }
            }
        }
        outcome.max_strain = worst - 1.0;
        if !violated || sweep == limit.max_iterations {
            break;
        }
        outcome.iterations += 1;
        let inv_dt = 1.0 / dt;
        for k in 0..n {
            if ws.count[k] > 0.0 {
                let w = 1.0 / ws.count[k];
                for c in 0..3 {
                    let dx = ws.corr[c * n + k] * w;
                    pos[c * n + k] += dx;
                    vel[c * n + k] += dx * inv_dt;
                }
            }
        }
    }
    outcome
}
