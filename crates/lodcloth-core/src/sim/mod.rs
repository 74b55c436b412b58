//! The pure simulation core: no I/O, no threads of its own, no clock, no
//! allocation per step. A large cloth's step may run half its work on a
//! thread the caller lends ([`Simulation::step_on`], [`Pair`]). A [`Simulation`] owns a cloth's topology, masses, parameters, loads
//! and [`State`]; [`Simulation::step`] advances it by exactly one fixed `dt`
//! and returns a [`StepReport`]. Numerical trouble comes back as data
//! (`report.finite == false`), never as a panic or an error.

mod bending;
mod contact;
mod crossings;
mod forces;
mod implicit;
mod live;
mod loads;
mod membrane;
mod model;
mod nodes;
mod paged;
mod pair;
mod par;
mod params;
mod real;
mod report;
mod selfcontact;
mod simd;
mod stability;
mod state;
mod strain;
mod topology;
mod validate;
pub mod vec3;
mod xpbd;

use std::sync::Arc;

pub use bending::{Assembled, Bending};
pub use contact::{Collider, Shape};
pub use crossings::{crossings, segment_meets_triangle, Crossing};
pub use forces::{SpringKernel, SpringTotals};
pub use live::GrabHeadroom;
pub use loads::{Grab, Loads, NodeLoad, Pin, PinPath, PinShift, Profile, Tether, Wind};
pub use membrane::{Membrane, Moduli};
pub use pair::{Lender, Pair, Serial};
pub use par::SPLIT_MIN_NODES;
pub use params::{
    CgSettings, Integrator, Material, SimParams, SpringClass, SpringCoeffs, SpringKind, SpringPrecision,
    StiffnessAdjustment, StrainLimit,
};
pub use real::Real;
pub use report::StepReport;
/// Closest point on a triangle (Ericson), shared with `mesh::locate`.
pub(crate) use selfcontact::point_triangle;
pub use selfcontact::{SelfContact, SelfOutcome, SELF_SPLIT_MIN_CANDIDATES};
pub use simd::{active_isa_name, force_path, VectorPath};
pub use stability::{amplification, dt_limit, modal_estimate, ModalEstimate};
pub use state::State;
pub use strain::StrainOutcome;
pub use topology::{GridShape, MeshNodes, Orientation, Padded, Run, SpringGroup, Topology};

use implicit::ImplicitInputs;
use model::{colour, Mixed, Model, Workspace};
use nodes::Sums;
use paged::Paged;
use par::{fused_last, halves_mut, node_split, stage_halves, stage_reads, Par};
use validate::{check_node_shares, invalid, validate_loads, validate_params};
use xpbd::SweepInputs;

/// Why a simulation could not be built or changed. Every variant names what
/// was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// A scalar parameter is out of its valid range.
    #[error("{name} = {value}: {reason}")]
    InvalidParameter {
        /// The parameter (e.g. `dt`, `masses[12]`).
        name: String,
        /// Its value.
        value: f64,
        /// What it must be.
        reason: &'static str,
    },
    /// Array sizes do not match the topology.
    #[error("{what} has {got} entries, the cloth has {expected} nodes")]
    SizeMismatch {
        /// The array.
        what: &'static str,
        /// Its length.
        got: usize,
        /// Nodes in the cloth.
        expected: usize,
    },
    /// A node index is outside the cloth.
    #[error("{what}: node {node} does not exist (the cloth has {n_nodes} nodes)")]
    NodeOutOfRange {
        /// What names the node (a pin, a force).
        what: &'static str,
        /// The index given.
        node: u32,
        /// Nodes in the cloth.
        n_nodes: usize,
    },
    /// A node is pinned twice.
    #[error("node {node} is pinned more than once")]
    DuplicatePin {
        /// The node.
        node: u32,
    },
    /// dt is beyond the predicted stability limit of the integrator.
    #[error(
        "dt = {dt:e} s is beyond the predicted stability limit of {integrator} ({limit:e} s; \
         ω_max = {omega_max:.1} rad/s, damping rate {damping_rate:.3} 1/s); \
         lower dt, soften the springs, choose another integrator, or force it"
    )]
    UnstableTimeStep {
        /// The integrator.
        integrator: Integrator,
        /// The time step asked for (s).
        dt: f64,
        /// The predicted largest stable time step (s).
        limit: f64,
        /// The highest natural frequency of the springs (rad/s).
        omega_max: f64,
        /// The damping rate of the stiffest mode (1/s).
        damping_rate: f64,
    },
}

/// How strictly [`Simulation::new`] checks stability.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StabilityCheck {
    /// Refuse a dt beyond the predicted limit of the integrator.
    #[default]
    Enforce,
    /// Accept it anyway (for stability experiments).
    Force,
}

/// A cloth being simulated. See the module docs.
#[derive(Debug, Clone)]
pub struct Simulation {
    model: Model,
    state: State,
    ws: Workspace,
    /// Acceleration at `state`; valid while `cached` is true.
    acc: Paged,
    totals: SpringTotals,
    cached: bool,
    /// `acc` is not written yet: the cache's forces wait as f32 spring
    /// forces in `ws.mixed` for symplectic Euler's update (or RK4's first
    /// pass), which turns them into accelerations in its own pass (one pass
    /// over the nodes fewer; see [`Simulation::ensure_cache_from`]).
    /// Anything else that reads
    /// `acc` writes it first ([`Simulation::flush`]).
    pending: bool,
    modal: ModalEstimate,
    last: Option<StepReport>,
    /// (time, step) of the state the clock counts from: the initial state or
    /// the last one set. Time after a step is `t0 + (step − s0)·dt`, computed
    /// from the count (no drift) yet correct when a state arrives from a run
    /// with another dt (a level switch).
    epoch: (f64, u64),
    /// Where a step splits its work in two (see [`Simulation::step_on`]).
    split: Option<usize>,
    /// The state's page offsets the buffers were last placed around, and
    /// the colours they got (see [`Simulation::place_buffers`]).
    placed: Option<([usize; 2], [usize; 12])>,
}

impl Simulation {
    /// Build a simulation starting from `state` (use [`State::at_rest`] for the
    /// rest shape). Validates every input; with [`StabilityCheck::Enforce`]
    /// refuses a dt beyond the integrator's predicted limit.
    pub fn new(
        topology: Arc<Topology>,
        masses: Vec<f64>,
        params: SimParams,
        loads: Loads,
        state: State,
        check: StabilityCheck,
    ) -> Result<Simulation, SimError> {
        let n = topology.n_nodes;
        validate_params(&params)?;
        if masses.len() != n {
            return Err(SimError::SizeMismatch {
                what: "masses",
                got: masses.len(),
                expected: n,
            });
        }
        if let Some((k, &m)) = masses.iter().enumerate().find(|(_, m)| !(m.is_finite() && **m > 0.0)) {
            return Err(SimError::InvalidParameter {
                name: format!("masses[{k}]"),
                value: m,
                reason: "node masses must be positive and finite",
            });
        }
        if state.pos.len() != 3 * n || state.vel.len() != 3 * n {
            return Err(SimError::SizeMismatch {
                what: "state",
                got: state.pos.len() / 3,
                expected: n,
            });
        }
        validate_loads(&loads, n)?;
        let mut pinned = vec![false; n];
        for pin in &loads.pins {
            if std::mem::replace(&mut pinned[pin.node as usize], true) {
                return Err(SimError::DuplicatePin { node: pin.node });
            }
        }
        // Tethers stiffen (and damp) their node like a spring to a fixed point.
        let mut tether_kc = vec![[0.0; 2]; if loads.tethers.is_empty() { 0 } else { n }];
        for t in &loads.tethers {
            let s = t.profile.max_abs();
            tether_kc[t.node as usize][0] += s * t.stiffness;
            tether_kc[t.node as usize][1] += s * t.damping;
        }
        let modal = modal_estimate(&topology, &params.material, &masses, &pinned, &tether_kc, params.drag);
        let limit = modal.dt_limit(params.integrator);
        if check == StabilityCheck::Enforce && params.dt > limit {
            return Err(SimError::UnstableTimeStep {
                integrator: params.integrator,
                dt: params.dt,
                limit,
                omega_max: modal.omega_max,
                damping_rate: modal.damping_rate,
            });
        }
        // Placed at the first step, with the other buffers (`place_buffers`).
        let inv_mass = Paged::from_fn(n, |k| if pinned[k] { 0.0 } else { 1.0 / masses[k] });
        let free = Paged::from_fn(n, |k| if pinned[k] { 0.0 } else { 1.0 });
        let masses = Paged::from_fn(n, |k| masses[k]);
        let ws = Workspace::new(&topology, &params, &loads);
        let mut sim = Simulation {
            model: Model {
                topology,
                masses,
                inv_mass,
                free,
                params,
                loads,
                grabs: Vec::new(),
                pin_shifts: Vec::new(),
            },
            acc: Paged::new(3 * n, colour(5)),
            state,
            ws,
            totals: SpringTotals::default(),
            cached: false,
            pending: false,
            modal,
            last: None,
            epoch: (0.0, 0),
            split: None,
            placed: None,
        };
        sim.split = node_split(&sim.model.topology);
        sim.epoch = sim.epoch_of(&sim.state);
        sim.apply_pins();
        Ok(sim)
    }

    /// The precision of the spring forces (see [`SpringPrecision`]).
    pub fn spring_precision(&self) -> SpringPrecision {
        if self.ws.mixed.is_some() {
            SpringPrecision::F32
        } else {
            SpringPrecision::F64
        }
    }

    /// Evaluate the spring forces in `precision` from the next evaluation
    /// on (allocates the f32 buffers once, here, never in a step).
    pub fn set_spring_precision(&mut self, precision: SpringPrecision) {
        if precision == self.spring_precision() {
            return;
        }
        self.ws.mixed = match precision {
            SpringPrecision::F64 => None,
            SpringPrecision::F32 => Some(Box::new(Mixed::new(&self.model.topology))),
        };
        self.invalidate();
    }

    /// The current state.
    pub fn state(&self) -> &State {
        &self.state
    }

    /// The epoch later step times count from for a cloth now at `state`:
    /// this one when it already gives `state`'s time at its step (a state
    /// of this run, or of a cloth rebuilt with the same dt), else the
    /// state itself. A cloth rebuilt in the middle of a run (new
    /// coefficients, a rollback) thus keeps the same step times, so a
    /// replay of the run is exact to the bit.
    fn epoch_of(&self, state: &State) -> (f64, u64) {
        let (t0, s0) = self.epoch;
        let same = state.step >= s0 && t0 + (state.step - s0) as f64 * self.model.params.dt == state.time;
        if same {
            self.epoch
        } else {
            (state.time, state.step)
        }
    }

    /// Replace the state (same node count), e.g. after a level switch or a
    /// rollback. Clears a divergence. Free nodes inside a collider are put
    /// on its surface (plus clearance), as a step's contact would.
    pub fn set_state(&mut self, state: State) -> Result<(), SimError> {
        let n = self.model.topology.n_nodes;
        if state.pos.len() != 3 * n || state.vel.len() != 3 * n {
            return Err(SimError::SizeMismatch {
                what: "state",
                got: state.pos.len() / 3,
                expected: n,
            });
        }
        self.epoch = self.epoch_of(&state);
        self.state = state;
        self.invalidate();
        self.last = None;
        self.apply_pins();
        // A state made elsewhere (another level's, mapped) may have nodes
        // inside a body: out along the nearest surface, as contact does.
        if !self.model.loads.colliders.is_empty() {
            self.ws.before.copy_from_slice(&self.state.pos);
            self.resolve_contact(self.state.time);
        }
        Ok(())
    }

    /// The topology.
    pub fn topology(&self) -> &Arc<Topology> {
        &self.model.topology
    }

    /// Node masses (kg).
    pub fn masses(&self) -> &[f64] {
        &self.model.masses
    }

    /// Parameters in force.
    pub fn params(&self) -> &SimParams {
        &self.model.params
    }

    /// Loads and pins in force.
    pub fn loads(&self) -> &Loads {
        &self.model.loads
    }

    /// Modal estimate computed when the simulation was built.
    pub fn modal(&self) -> &ModalEstimate {
        &self.modal
    }

    /// Predicted largest stable dt of the configured integrator.
    pub fn dt_limit(&self) -> f64 {
        self.modal.dt_limit(self.model.params.integrator)
    }

    /// Report of the last step, if any since the state was last set.
    pub fn last_report(&self) -> Option<&StepReport> {
        self.last.as_ref()
    }

    /// True when the last step produced a non-finite value.
    pub fn diverged(&self) -> bool {
        self.last.is_some_and(|r| !r.finite)
    }

    /// Acceleration at the current state, [x…, y…, z…] (m/s²).
    pub fn accelerations(&mut self) -> &[f64] {
        let par = Par {
            pair: &Serial,
            split: self.split,
            isa: simd::current(),
        };
        simd::run(
            par.isa,
            #[inline(always)]
            || {
                self.ensure_cache(par);
                self.flush(par);
            },
        );
        &self.acc
    }

    /// The node where a step splits its work in two, for cloths of at least
    /// [`SPLIT_MIN_NODES`] nodes.
    pub fn split(&self) -> Option<usize> {
        self.split
    }

    /// Every force on each node except the springs' at (t, pos, vel), SoA,
    /// into `out`: scene loads, wind, gravity and drag (`m·g − m·drag·v`).
    /// Pinned nodes get zero. Estimation subtracts this from `m·a` to recover
    /// the spring forces (Sung 2018 §5.1).
    ///
    /// # Panics
    /// When a slice is not 3n long.
    pub fn external_forces(&mut self, t: f64, pos: &[f64], vel: &[f64], out: &mut [f64]) {
        let n = self.model.topology.n_nodes;
        assert!(
            pos.len() == 3 * n && vel.len() == 3 * n && out.len() == 3 * n,
            "field sizes"
        );
        self.model.external_forces(t, pos, vel, out, &mut self.ws.normals);
    }

    /// Advance by one `dt`. Never fails and never allocates. After a
    /// divergence it does nothing and returns the divergence report again.
    pub fn step(&mut self) -> StepReport {
        self.step_on(&Serial)
    }

    /// [`Simulation::step`] with a second thread lent by `pair`. A cloth of
    /// at least [`SPLIT_MIN_NODES`] nodes always splits its step in two
    /// fixed halves (springs on each side of a middle node, then the few
    /// across it; node passes by halves); `pair` decides only whether they
    /// run at the same time, so the result is bit-identical with [`Serial`]
    /// and with a [`Lender`]. Smaller cloths ignore `pair`.
    pub fn step_on(&mut self, pair: &dyn Pair) -> StepReport {
        self.step_with(pair, true)
    }

    /// [`Simulation::step`] without the springs' figures: the report's
    /// `elastic_energy` and `max_strain` are NaN, everything else is as
    /// [`Simulation::step`] gives it (the same state to the bit, `finite`
    /// from every position and velocity). The spring kernel then sums
    /// neither the springs' energy nor their largest strain, which is what
    /// a step with few readers of its report costs: a peer's step computes
    /// no energies, and the daemon reads them once per published frame
    /// (64×64 f32 step on the AVX2 path: 9 % fewer instructions).
    pub fn step_lean(&mut self) -> StepReport {
        self.step_with(&Serial, false)
    }

    /// [`Simulation::step_lean`] with a second thread lent by `pair` (see
    /// [`Simulation::step_on`]).
    pub fn step_on_lean(&mut self, pair: &dyn Pair) -> StepReport {
        self.step_with(pair, false)
    }

    fn step_with(&mut self, pair: &dyn Pair, stats: bool) -> StepReport {
        self.place_buffers();
        let par = Par {
            pair,
            split: self.split,
            isa: simd::current(),
        };
        // Compiled for the CPU's best vector instruction set (see `simd`):
        // the node loops of the integrators, the strain check and the
        // report all run inlined into this closure (halves run on another
        // thread are dispatched again there, see `Par::both`).
        if stats {
            simd::run(
                par.isa,
                #[inline(always)]
                || self.step_impl::<true>(par),
            )
        } else {
            simd::run(
                par.isa,
                #[inline(always)]
                || self.step_impl::<false>(par),
            )
        }
    }

    #[inline(always)]
    fn step_impl<const STATS: bool>(&mut self, par: Par) -> StepReport {
        let stats = STATS;
        if let Some(last) = self.last.filter(|r| !r.finite) {
            return last;
        }
        let xpbd = self.model.params.integrator == Integrator::Xpbd;
        let mut bending_energy = 0.0;
        // XPBD needs no acceleration: its constraints replace the springs' forces.
        if !xpbd {
            self.ensure_cache(par);
            if !matches!(
                self.model.params.integrator,
                Integrator::SymplecticEuler | Integrator::Rk4
            ) {
                self.flush(par);
            }
        }
        let dt = self.model.params.dt;
        let t0 = self.state.time;
        let mut solver = (0, 0.0);
        // The report sums of a fused last pass (symplectic Euler, RK4).
        let mut fused = None;
        if !self.ws.before.is_empty() {
            self.ws.before.copy_from_slice(&self.state.pos);
        }
        match self.model.params.integrator {
            // The update, the kernel's f32 copies and the report's sums in one pass.
            Integrator::SymplecticEuler => fused = Some(self.symplectic(dt, par)),
            Integrator::ExplicitEuler => {
                // x moves with the old v.
                let mid = par.flat_mid(self.acc.len());
                let (p0, p1) = self.state.pos.split_at_mut(mid);
                let (v0, v1) = self.state.vel.split_at_mut(mid);
                let (a0, a1) = self.acc.split_at(mid);
                par.both(
                    #[inline(always)]
                    || nodes::explicit_euler(p0, v0, a0, dt),
                    #[inline(always)]
                    || nodes::explicit_euler(p1, v1, a1, dt),
                );
            }
            Integrator::Rk4 => fused = Some(self.rk4(t0, dt, par)),
            Integrator::ImplicitEuler => {
                let m = &self.model;
                let inputs = ImplicitInputs {
                    topology: &m.topology,
                    material: &m.params.material,
                    adjust_ratio: m.adjust_ratio(),
                    masses: &m.masses,
                    free: &m.free,
                    drag: m.params.drag,
                    dt,
                    cg: m.params.cg,
                };
                let ws = self
                    .ws
                    .implicit
                    .as_mut()
                    .expect("implicit workspace exists for implicit Euler");
                let out = implicit::step(&inputs, &mut self.state.pos, &mut self.state.vel, &self.acc, ws);
                solver = (out.iterations, out.relative_residual);
            }
            Integrator::Xpbd => {
                let ws = self.ws.xpbd.as_deref_mut().expect("XPBD workspace exists for XPBD");
                let s = &mut self.state;
                self.model
                    .external_forces(t0, &s.pos, &s.vel, &mut ws.ext, &mut self.ws.normals);
                xpbd::predict(&self.model.inv_mass, dt, &mut s.pos, &mut s.vel, ws);
            }
        }
        self.state.step += 1;
        // Time from the step count, not by accumulation: no drift over long runs.
        self.state.time = self.epoch.0 + (self.state.step - self.epoch.1) as f64 * dt;
        let pins_finite = self.apply_pins();
        if xpbd {
            // The constraints see the pins where they are at the step's end.
            let m = &self.model;
            let inputs = SweepInputs {
                topology: &m.topology,
                material: &m.params.material,
                adjust_ratio: m.adjust_ratio(),
                inv_mass: &m.inv_mass,
                dt,
            };
            let ws = self.ws.xpbd.as_deref_mut().expect("XPBD workspace exists for XPBD");
            bending_energy = xpbd::sweep(&inputs, &mut self.state.pos, &mut self.state.vel, ws);
        }

        // Strain limiting runs before the force evaluation, not after it: its
        // first full pass finds the over-long springs itself (and returns at
        // once when there are none), so one evaluation per step serves both the
        // report and the next step. Checking the kernel's max strain first and
        // evaluating again after a correction cost a second full force
        // evaluation on every limited step (most steps of the hanging scene).
        let mut strain_iterations = 0;
        if let (Some(limit), Some(ws)) = (&self.model.params.strain_limit, self.ws.strain.as_mut()) {
            let out = strain::limit(
                &self.model.topology,
                &self.model.inv_mass,
                limit,
                dt,
                &mut self.state.pos,
                &mut self.state.vel,
                ws,
            );
            strain_iterations = out.iterations;
        }
        // Contact last, so no state a reader sees has a node inside a body.
        let contacts = self.resolve_contact(t0);
        // Self-contact after the bodies': what a reader sees never has the
        // cloth through itself (sim/selfcontact, "What is guaranteed").
        let self_contact = match (&self.model.params.self_contact, self.ws.selfc.as_deref_mut()) {
            (Some(settings), Some(ws)) => selfcontact::resolve(
                settings,
                dt,
                &self.ws.before,
                &mut self.state.pos,
                &mut self.state.vel,
                &self.model.inv_mass,
                ws,
                par.pair,
            ),
            _ => SelfOutcome::default(),
        };
        let moved_by_self = self_contact.proximities + self_contact.impacts + self_contact.zone_rounds > 0;
        // The fused pass's f32 copies and sums describe the final state when
        // nothing but the pins (which write their copies) moved a node since,
        // and every node was finite before the pins (so the pinned nodes'
        // massless terms were exact zeros, as they are now).
        let fused = fused
            .filter(|s: &Sums| pins_finite && strain_iterations == 0 && contacts == 0 && !moved_by_self && s.finite());
        self.invalidate();
        if xpbd {
            // No force evaluation: the report's spring figures from one pass
            // of lengths over the final state.
            let m = &self.model;
            self.totals = if stats {
                xpbd::spring_totals(&m.topology, &m.params.material, &self.state.pos, bending_energy)
            } else {
                SpringTotals::UNMEASURED
            };
        } else {
            self.ensure_cache_from(par, fused.is_some(), stats);
        }

        let mut report = match fused {
            Some(sums) => self.report_of(sums, solver, strain_iterations, stats),
            None => self.measure(solver, strain_iterations, par, stats),
        };
        report.contacts = contacts;
        report.self_contact = self_contact;
        self.last = Some(report);
        report
    }

    /// Contact for the move from `ws.before` at `t0` to the current state
    /// (see [`contact`]); the contacts resolved.
    #[inline(always)]
    fn resolve_contact(&mut self, t0: f64) -> u32 {
        contact::resolve(
            &self.model.loads.colliders,
            (t0, self.state.time),
            &self.ws.before,
            &mut self.state.pos,
            &mut self.state.vel,
            &self.model.free,
            &mut self.ws.near,
        )
    }

    /// Overwrite pinned nodes with their prescribed position and velocity at
    /// the current time (and their f32 copies, with f32 springs); false when
    /// one of them is not finite.
    fn apply_pins(&mut self) -> bool {
        let t = self.state.time;
        let n = self.model.topology.n_nodes;
        let shifts = &self.model.pin_shifts;
        let mut finite = true;
        for (i, pin) in self.model.loads.pins.iter().enumerate() {
            let (mut p, mut v) = pin.at(t);
            if let Some(shift) = shifts.get(i) {
                let (dp, dv) = shift.at(t);
                for c in 0..3 {
                    p[c] += dp[c];
                    v[c] += dv[c];
                }
            }
            let k = pin.node as usize;
            self.state.set_position(k, p);
            self.state.set_velocity(k, v);
            if let Some(m) = self.ws.mixed.as_deref_mut() {
                for c in 0..3 {
                    m.pos[c * n + k] = p[c] as f32;
                    m.vel[c * n + k] = v[c] as f32;
                }
            }
            finite &= p.iter().chain(&v).all(|x| x.is_finite());
        }
        finite
    }

    /// The cached acceleration of the state evaluated if it is not, without
    /// the springs' figures (a step's report takes them from the
    /// evaluation at its end, [`Simulation::ensure_cache_from`]).
    #[inline(always)]
    fn ensure_cache(&mut self, par: Par) {
        self.ensure_cache_from(par, false, false);
    }

    /// [`Simulation::ensure_cache`]; `rounded`: the f32 copies of the state
    /// are already written (by a fused last pass), the kernel need not
    /// round them again; `stats`: with the springs' figures, into
    /// `totals`.
    #[inline(always)]
    fn ensure_cache_from(&mut self, par: Par, rounded: bool, stats: bool) {
        if !self.cached {
            let s = &self.state;
            // Symplectic Euler and RK4 take the f32 spring forces as they are.
            let defer = matches!(
                self.model.params.integrator,
                Integrator::SymplecticEuler | Integrator::Rk4
            );
            let (totals, pending) = self.model.accelerations(
                s.time,
                &s.pos,
                &s.vel,
                &mut self.acc,
                &mut self.ws,
                par,
                rounded,
                defer,
                stats,
            );
            (self.totals, self.pending) = (totals, pending);
            self.cached = true;
        }
    }

    /// The cache complete: `acc` written if the forces wait in f32.
    #[inline(always)]
    fn flush(&mut self, par: Par) {
        if self.pending {
            let (pos, vel) = (&self.state.pos[..], &self.state.vel[..]);
            let f = self.ws.force.window_away_from([pos.as_ptr(), vel.as_ptr()]);
            self.model
                .to_accelerations(vel, f, &mut self.acc, self.ws.mixed.as_deref_mut(), par);
            self.pending = false;
        }
    }

    /// The cache no longer describes the state: evaluated again before it
    /// is read, the f32 forces waiting for the update (if any) cleared,
    /// since the kernel adds to them.
    fn invalidate(&mut self) {
        if std::mem::take(&mut self.pending) {
            if let Some(m) = self.ws.mixed.as_deref_mut() {
                m.force.fill(0.0);
            }
        }
        self.cached = false;
    }

    /// Symplectic Euler's update of the state from the cached acceleration,
    /// fused with the f32 copies for the next force evaluation and the
    /// report's sums (see [`nodes`]); returns the sums.
    #[inline(always)]
    fn symplectic(&mut self, dt: f64, par: Par) -> Sums {
        let from_forces = std::mem::take(&mut self.pending);
        fused_last(
            par,
            &self.model,
            &mut self.state,
            self.ws.mixed.as_deref_mut(),
            (!from_forces).then_some(&self.acc[..]),
            None,
            dt,
        )
    }

    /// Classic RK4 on y = (x, v), y' = (v, a(t, x, v)); k1 is the cached
    /// acceleration. With f32 springs each pass that makes a stage writes
    /// its f32 copies for the kernel, and the last pass those of the new
    /// state and the report's sums (returned; see [`nodes`]). With f32
    /// springs and no other force, each pass that reads a stage's
    /// acceleration makes it from the kernel's f32 forces
    /// ([`nodes::StageForces`]): k1 waits in them since the last step's
    /// evaluation (`pending`), k2–k4 since their own.
    #[inline(always)]
    fn rk4(&mut self, t0: f64, dt: f64, par: Par) -> Sums {
        let from_forces = std::mem::take(&mut self.pending);
        let model = &self.model;
        let n = model.topology.n_nodes;
        let Workspace {
            stage_pos,
            stage_vel,
            sum_pos,
            sum_vel,
            stage_acc,
            mixed,
            ..
        } = &mut self.ws;
        let (pos, vel) = (&self.state.pos[..], &self.state.vel[..]);
        let len = pos.len();
        let mid = par.flat_mid(len);
        // Plain slices of one length, bound once: indexing through `Paged`'s
        // deref inside the loops kept their bounds checks and scalar code.
        {
            let k1 = (!from_forces).then(|| &self.acc[..len]);
            let (r0, r1) = stage_reads(pos, vel, k1, mid);
            let (w0, w1) = halves_mut(
                [
                    &mut sum_pos[..len],
                    &mut sum_vel[..len],
                    &mut stage_pos[..len],
                    &mut stage_vel[..len],
                ],
                mid,
            );
            let ((c0, c1), (f0, f1)) = stage_halves(mixed.as_deref_mut(), model, mid, true, from_forces);
            par.both(
                #[inline(always)]
                || nodes::rk4_first(r0, w0, c0, f0, dt),
                #[inline(always)]
                || nodes::rk4_first(r1, w1, c1, f1, dt),
            );
        }
        let mut stage_pos = std::mem::take(stage_pos);
        let mut stage_vel = std::mem::take(stage_vel);
        let mut stage_acc = std::mem::take(stage_acc);
        // k2, k3 at the midpoint, k4 at the end.
        for (weight, t_stage, next_scale) in [
            (2.0, 0.5 * dt, Some(0.5 * dt)),
            (2.0, 0.5 * dt, Some(dt)),
            (1.0, dt, None),
        ] {
            // Pinned nodes are where their paths put them at the stage's time:
            // extrapolating them with the start-of-step velocity (their
            // acceleration is 0) made RK4 first order for moving pins
            // (tests/convergence.rs). Fixed pins are unchanged by this.
            for pin in &model.loads.pins {
                let (p, v) = pin.at(t0 + t_stage);
                let k = pin.node as usize;
                for c in 0..3 {
                    stage_pos[c * n + k] = p[c];
                    stage_vel[c * n + k] = v[c];
                }
                if let Some(m) = self.ws.mixed.as_deref_mut() {
                    for c in 0..3 {
                        m.pos[c * n + k] = p[c] as f32;
                        m.vel[c * n + k] = v[c] as f32;
                    }
                }
            }
            // The stage's f32 copies were written with it (and its pins just now).
            let rounded = self.ws.mixed.is_some();
            let (_, from_forces) = model.accelerations(
                t0 + t_stage,
                &stage_pos,
                &stage_vel,
                &mut stage_acc,
                &mut self.ws,
                par,
                rounded,
                true,
                // A stage's figures are never reported.
                false,
            );
            let acc = (!from_forces).then(|| &stage_acc[..len]);
            let (r0, r1) = stage_reads(pos, vel, acc, mid);
            let (w0, w1) = halves_mut(
                [
                    &mut self.ws.sum_pos[..len],
                    &mut self.ws.sum_vel[..len],
                    &mut stage_pos[..len],
                    &mut stage_vel[..len],
                ],
                mid,
            );
            // The stage after k4 is never evaluated: no copies for it.
            let ((c0, c1), (f0, f1)) = stage_halves(
                self.ws.mixed.as_deref_mut(),
                model,
                mid,
                next_scale.is_some(),
                from_forces,
            );
            par.both(
                #[inline(always)]
                || nodes::rk4_stage(r0, w0, c0, f0, weight, next_scale),
                #[inline(always)]
                || nodes::rk4_stage(r1, w1, c1, f1, weight, next_scale),
            );
        }
        self.ws.stage_pos = stage_pos;
        self.ws.stage_vel = stage_vel;
        self.ws.stage_acc = stage_acc;
        let ws = &mut self.ws;
        fused_last(
            par,
            &self.model,
            &mut self.state,
            ws.mixed.as_deref_mut(),
            Some(&ws.sum_vel),
            Some(&ws.sum_pos),
            dt / 6.0,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// The split step against the whole one on the same cloth: the halves
    /// must add up to the same step, for every integrator, with wind,
    /// strain limiting and pins in play. Only the order of additions at the
    /// seam differs, so the states agree to rounding. (The tests in
    /// `tests/two_threads.rs` compare one thread with two, the same split
    /// both times; this one is the independent check of the split itself.)
    #[test]
    fn a_split_step_is_the_whole_step_to_rounding() {
        let scenes = [
            (include_str!("../../../../config/scenes/flag-2to1-wind.toml"), "flag"),
            (include_str!("../../../../config/scenes/curtain-shaken.toml"), "curtain"),
        ];
        for (text, name) in scenes {
            let base = Scene::from_toml(text, name).expect("shipped scene");
            for integrator in Integrator::ALL {
                let mut scene = base.clone();
                scene.params.integrator = integrator;
                scene.stability = StabilityCheck::Force;
                let (nx, ny) = (128, SPLIT_MIN_NODES / 128);
                let probe = scene.build_at(nx, ny).expect("builds");
                scene.params.dt = 0.3
                    * probe
                        .dt_limit()
                        .min(probe.modal().dt_limit(Integrator::SymplecticEuler));
                let mut split = scene.build_at(nx, ny).expect("builds");
                assert!(split.split().is_some());
                let mut whole = split.clone();
                whole.split = None;
                let steps = if integrator == Integrator::ImplicitEuler { 5 } else { 30 };
                for _ in 0..steps {
                    let (a, b) = (split.step(), whole.step());
                    assert!(a.finite && b.finite, "{name} {integrator} diverged");
                    let rel = |x: f64, y: f64| (x - y).abs() / x.abs().max(y.abs()).max(1e-300);
                    assert!(
                        rel(a.kinetic_energy, b.kinetic_energy) < 1e-9,
                        "{name} {integrator}: kinetic energy"
                    );
                    assert!(
                        rel(a.elastic_energy, b.elastic_energy) < 1e-9,
                        "{name} {integrator}: elastic energy"
                    );
                }
                let (s, w) = (split.state(), whole.state());
                let scale = w.vel.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-9);
                let dv = s.vel.iter().zip(&w.vel).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                let dx = s.pos.iter().zip(&w.pos).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                assert!(
                    dv <= 1e-9 * scale,
                    "{name} {integrator}: velocities differ by {dv:e} (scale {scale:e})"
                );
                assert!(dx <= 1e-12, "{name} {integrator}: positions differ by {dx:e} m");
            }
        }
    }
}
