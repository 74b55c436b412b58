//! What a step reports: [`StepReport`], and how the report of the current
//! state is made from the fused pass's sums or a pass of its own.

use super::nodes::{self, Sums, LANES, NO_SUMS};
use super::par::{halves, inlined, Par};
use super::Simulation;

/// What one step did and what the new state looks like.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// Steps taken so far (after this one).
    pub step: u64,
    /// Simulated time after this step (s).
    pub time: f64,
    /// False when any position or velocity is NaN or infinite: the simulation
    /// has diverged and will not step again until its state is replaced.
    pub finite: bool,
    /// Σ ½ m |v|² over free nodes (J).
    pub kinetic_energy: f64,
    /// Σ ½ K (L − L0)² over all springs (J).
    pub elastic_energy: f64,
    /// Σ −m g·x over free nodes (J), zero at the origin.
    pub gravity_energy: f64,
    /// Largest strain L/L0 − 1 per spring kind ([`super::SpringKind::index`]).
    pub max_strain: [f64; 3],
    /// Conjugate-gradient iterations (implicit Euler only).
    pub solver_iterations: u32,
    /// Final relative residual of the CG solve (implicit Euler only).
    pub solver_residual: f64,
    /// Strain-limiting sweeps that corrected something.
    pub strain_iterations: u32,
    /// Node–body contacts resolved this step (0 without colliders).
    pub contacts: u32,
    /// What self-contact did this step (all zero without it).
    pub self_contact: super::SelfOutcome,
}

impl StepReport {
    /// Kinetic + elastic + gravitational energy (J).
    pub fn total_energy(&self) -> f64 {
        self.kinetic_energy + self.elastic_energy + self.gravity_energy
    }

    /// Largest strain over all spring kinds.
    pub fn max_strain_overall(&self) -> f64 {
        self.max_strain.iter().copied().fold(f64::NEG_INFINITY, f64::max)
    }
}

impl Simulation {
    /// The report of the current state. One pass over the nodes gives the
    /// energies and finiteness, with `LANES` partial sums (a sequential sum
    /// is one long chain of dependent additions, several µs at 64×64); a
    /// split step sums each half's lanes and adds the halves lane by lane.
    #[inline(always)]
    pub(super) fn measure(&self, solver: (u32, f64), strain_iterations: u32, par: Par, stats: bool) -> StepReport {
        let n = self.model.topology.n_nodes;
        let (pos, vel) = (&self.state.pos, &self.state.vel);
        let (masses, free) = (&self.model.masses[..n], &self.model.free[..n]);
        let (px, rest) = pos.split_at(n);
        let (py, pz) = rest.split_at(n);
        let (vx, rest) = vel.split_at(n);
        let (vy, vz) = rest.split_at(n);
        #[inline(always)]
        fn arr<const N: usize>(s: &[f64], k: usize) -> [f64; N] {
            *<&[f64; N]>::try_from(&s[k..k + N]).expect("N")
        }
        /// Nodes `k..k+N` into lanes `0..N` of the partial sums.
        #[inline(always)]
        fn block<const N: usize>(k: usize, [masses, free, px, py, pz, vx, vy, vz]: [&[f64]; 8], s: &mut Sums) {
            let block = nodes::Block::<N> {
                mass: arr(masses, k),
                free: arr(free, k),
                x: [arr(px, k), arr(py, k), arr(pz, k)],
                v: [arr(vx, k), arr(vy, k), arr(vz, k)],
            };
            nodes::add_to_sums(&block, s);
        }
        let sums = inlined(
            #[inline(always)]
            |arrays: [&[f64]; 8], out: &mut Sums| {
                let n = arrays[0].len();
                let mut s = NO_SUMS;
                let mut k = 0;
                while k + LANES <= n {
                    block::<LANES>(k, arrays, &mut s);
                    k += LANES;
                }
                for k in k..n {
                    block::<1>(k, arrays, &mut s);
                }
                *out = s;
            },
        );
        let cut = par.split.unwrap_or(n);
        let (lo, hi) = halves([masses, free, px, py, &pz[..n], vx, vy, &vz[..n]], cut);
        let (mut s0, mut s1) = (NO_SUMS, NO_SUMS);
        par.both(
            #[inline(always)]
            || sums(lo, &mut s0),
            #[inline(always)]
            || sums(hi, &mut s1),
        );
        if par.split.is_some() {
            nodes::merge(&mut s0, &s1);
        }
        self.report_of(s0, solver, strain_iterations, stats)
    }

    /// The report of the current state from its partial sums (see [`nodes`]).
    pub(super) fn report_of(&self, sums: Sums, solver: (u32, f64), strain_iterations: u32, stats: bool) -> StepReport {
        let (ke, pe, sums_finite) = sums.finish(self.model.params.gravity);
        // The sums are finite exactly when every position and velocity is
        // (what `State::is_finite` checks; see `nodes::Sums`).
        // A lean step's figures are NaN by design (a non-finite force shows
        // in the next step's velocities).
        let finite = sums_finite && (!stats || self.totals.elastic_energy.is_finite());
        StepReport {
            step: self.state.step,
            time: self.state.time,
            finite,
            kinetic_energy: ke,
            elastic_energy: self.totals.elastic_energy,
            gravity_energy: pe,
            max_strain: self.totals.max_strain,
            solver_iterations: solver.0,
            solver_residual: solver.1,
            strain_iterations,
            contacts: 0,
            self_contact: super::SelfOutcome::default(),
        }
    }
}
