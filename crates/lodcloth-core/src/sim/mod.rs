//! The pure simulation core: no I/O, no threads of its own, no clock, no
//! allocation per step. A large cloth's step may run half its work on a
//! thread the caller lends ([`Simulation::step_on`], [`Pair`]). A [`Simulation`] owns a cloth's topology, masses, parameters, loads
//! and [`State`]; [`Simulation::step`] advances it by exactly one fixed `dt`
//! and returns a [`StepReport`]. Numerical trouble comes back as data
//! (`report.finite == false`), never as a panic or an error.

mod bending;
mod contact;
mod forces;
mod implicit;
mod live;
mod loads;
mod membrane;
mod nodes;
mod paged;
mod pair;
mod params;
mod real;
mod simd;
mod stability;
mod state;
mod strain;
mod topology;
pub mod vec3;
mod xpbd;

use std::sync::Arc;

pub use bending::Bending;
pub use contact::{Collider, Shape};
pub use forces::{SpringKernel, SpringTotals};
pub use live::GrabHeadroom;
pub use loads::{Grab, Loads, NodeLoad, Pin, PinPath, PinShift, Profile, Tether, Wind};
pub use membrane::{Membrane, Moduli};
pub use pair::{Lender, Pair, Serial};
pub use params::{
    CgSettings, Integrator, Material, SimParams, SpringClass, SpringCoeffs, SpringKind, SpringPrecision,
    StiffnessAdjustment, StrainLimit,
};
pub use real::Real;
pub use simd::{active_isa_name, force_path, VectorPath};
pub use stability::{amplification, dt_limit, modal_estimate, ModalEstimate};
pub use state::State;
pub use strain::StrainOutcome;
pub use topology::{GridShape, Orientation, Padded, Run, SpringGroup, Topology};

use forces::KernelScratch;
use implicit::{ImplicitInputs, ImplicitWorkspace};
use nodes::{Sums, LANES, NO_SUMS};
use paged::Paged;
use simd::Isa;
use strain::StrainWorkspace;
use xpbd::{SweepInputs, XpbdWorkspace};

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
    /// Largest strain L/L0 − 1 per spring kind ([`SpringKind::index`]).
    pub max_strain: [f64; 3],
    /// Conjugate-gradient iterations (implicit Euler only).
    pub solver_iterations: u32,
    /// Final relative residual of the CG solve (implicit Euler only).
    pub solver_residual: f64,
    /// Strain-limiting sweeps that corrected something.
    pub strain_iterations: u32,
    /// Node–body contacts resolved this step (0 without colliders).
    pub contacts: u32,
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

/// How strictly [`Simulation::new`] checks stability.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StabilityCheck {
    /// Refuse a dt beyond the predicted limit of the integrator.
    #[default]
    Enforce,
    /// Accept it anyway (for stability experiments).
    Force,
}

/// Scratch buffers; allocated once when the simulation is built.
#[derive(Debug, Clone)]
struct Workspace {
    kernel: KernelScratch<f64>,
    /// Zero between evaluations; each evaluation uses a window of it placed
    /// away from the positions and velocities it reads (see [`paged`]).
    force: Paged,
    normals: Vec<f64>,
    /// RK4: stage position/velocity, accumulated increments, stage
    /// acceleration; each at its own page offset (see [`paged`]).
    stage_pos: Paged,
    stage_vel: Paged,
    sum_pos: Paged,
    sum_vel: Paged,
    stage_acc: Paged,
    implicit: Option<ImplicitWorkspace>,
    strain: Option<StrainWorkspace>,
    /// Positions at the start of the step, for contact's swept test, and
    /// contact's marks, one per node (both empty without colliders).
    before: Vec<f64>,
    near: Vec<u8>,
    /// Springs in f32 ([`SpringPrecision::F32`]); None in f64.
    mixed: Option<Box<Mixed>>,
    /// XPBD's sweep order and buffers (XPBD only).
    xpbd: Option<Box<XpbdWorkspace>>,
}

/// The f32 side of a step with [`SpringPrecision::F32`]: positions and
/// velocities rounded for the kernel, and its forces (zero between
/// evaluations, like [`Workspace::force`]).
#[derive(Debug, Clone)]
struct Mixed {
    pos: Paged<f32>,
    vel: Paged<f32>,
    force: Paged<f32>,
    kernel: KernelScratch<f32>,
}

impl Mixed {
    /// Each buffer a third of a page from the others: at 64×64 every f32
    /// component array is 16 KiB, so the nine streams of the kernel would
    /// otherwise share one L1 set (see [`paged`]); measured 45 µs a 64²
    /// symplectic step with plain allocations against 36 placed.
    fn new(topology: &Topology) -> Mixed {
        let n3 = 3 * topology.n_nodes;
        Mixed {
            pos: Paged::new(n3, 0),
            vel: Paged::new(n3, 1344),
            force: Paged::new(n3, 2688),
            kernel: KernelScratch::new(topology),
        }
    }
}

/// `dst[i] = src[i]` rounded to f32 (to nearest, ties to even: the same on
/// every instruction set).
#[inline(always)]
fn round_into(src: &[f64], dst: &mut [f32]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s as f32;
    }
}

/// Page offset of the `i`th field buffer the integrators stream through
/// together (RK4's five and the acceleration): ten cache lines apart.
fn colour(i: usize) -> usize {
    i * 640
}

impl Workspace {
    fn new(topology: &Topology, params: &SimParams, loads: &Loads) -> Workspace {
        let n3 = 3 * topology.n_nodes;
        let rk = if params.integrator == Integrator::Rk4 { n3 } else { 0 };
        Workspace {
            kernel: KernelScratch::new(topology),
            force: Paged::new(n3, 0),
            normals: if loads.wind.is_some() {
                vec![0.0; n3]
            } else {
                Vec::new()
            },
            stage_pos: Paged::new(rk, colour(0)),
            stage_vel: Paged::new(rk, colour(1)),
            sum_pos: Paged::new(rk, colour(2)),
            sum_vel: Paged::new(rk, colour(3)),
            stage_acc: Paged::new(rk, colour(4)),
            implicit: (params.integrator == Integrator::ImplicitEuler).then(|| ImplicitWorkspace::new(topology)),
            strain: params.strain_limit.map(|_| StrainWorkspace::new(topology)),
            before: if loads.colliders.is_empty() {
                Vec::new()
            } else {
                vec![0.0; n3]
            },
            near: if loads.colliders.is_empty() {
                Vec::new()
            } else {
                vec![0; topology.n_nodes]
            },
            mixed: None,
            xpbd: (params.integrator == Integrator::Xpbd).then(|| Box::new(XpbdWorkspace::new(topology))),
        }
    }
}

/// Read-only model data shared by every force evaluation.
#[derive(Debug, Clone)]
struct Model {
    topology: Arc<Topology>,
    masses: Vec<f64>,
    /// 1/m for free nodes, 0 for pinned ones.
    inv_mass: Vec<f64>,
    /// 1 for free nodes, 0 for pinned ones.
    free: Vec<f64>,
    params: SimParams,
    loads: Loads,
    /// Live grabs (see [`Simulation::set_grabs`]).
    grabs: Vec<Grab>,
    /// Live pin moves, one per entry of `loads.pins` (empty when none was
    /// ever moved; see [`Simulation::shift_pins`]).
    pin_shifts: Vec<PinShift>,
}

impl Model {
    fn adjust_ratio(&self) -> f64 {
        self.params
            .stiffness_adjustment
            .map_or(f64::INFINITY, |a| 1.0 + a.allowed)
    }

    /// Every force but the springs' and the bending stencils' at (t, pos,
    /// vel) into `out`: loads, wind, grabs, gravity and drag; zero on pinned
    /// nodes.
    fn external_forces(&self, t: f64, pos: &[f64], vel: &[f64], out: &mut [f64], normals: &mut [f64]) {
        let n = self.topology.n_nodes;
        out.fill(0.0);
        self.loads.add_forces(&self.topology, t, pos, vel, out, normals);
        for grab in &self.grabs {
            grab.add_force(pos, vel, out);
        }
        let (g, drag) = (self.params.gravity, self.params.drag);
        for c in 0..3 {
            for k in 0..n {
                let i = c * n + k;
                out[i] = self.free[k] * (out[i] + self.masses[k] * (g[c] - drag * vel[i]));
            }
        }
    }

    /// True when forces other than the springs' are added to the f64 force
    /// buffer (bending stencils, loads, wind, tethers, grabs). Without them,
    /// and with f32 springs, that buffer stays zero and the last pass does not
    /// read it.
    fn f64_forces(&self) -> bool {
        !self.topology.bending.is_empty() || self.loads.adds_forces() || !self.grabs.is_empty()
    }

    /// Accelerations at (t, pos, vel) into `acc`; returns the spring by-products.
    ///
    /// `ws.force` is all zeros on entry and on return: the last pass, which
    /// turns forces into accelerations, clears it while it is in cache,
    /// instead of a separate pass to clear it before the next evaluation.
    /// `rounded`: with f32 springs, their copies of pos and vel are already
    /// written (by the pass that made pos and vel, see [`nodes`]). `stats`:
    /// sum the springs' energy and largest strains (else
    /// [`SpringTotals::UNMEASURED`]): only an evaluation whose figures a
    /// report shows needs them.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn accelerations(
        &self,
        t: f64,
        pos: &[f64],
        vel: &[f64],
        acc: &mut [f64],
        ws: &mut Workspace,
        par: Par,
        rounded: bool,
        defer: bool,
        stats: bool,
    ) -> (SpringTotals, bool) {
        let topo = &*self.topology;
        debug_assert!(ws.force.all_zero(), "force buffer not cleared");
        let f = ws.force.window_away_from([pos.as_ptr(), vel.as_ptr()]);
        let (material, adjust) = (&self.params.material, self.adjust_ratio());
        let mut totals = match (ws.mixed.as_deref_mut(), par.split) {
            (None, Some(split)) => forces::spring_forces_split(
                topo,
                &ws.kernel.rest,
                material,
                adjust,
                pos,
                vel,
                f,
                split,
                par.pair,
                par.isa,
                stats,
            ),
            (None, None) => forces::spring_forces(topo, material, adjust, pos, vel, f, &mut ws.kernel, stats),
            (Some(m), split) => {
                if !rounded {
                    let mid = par.flat_mid(pos.len());
                    let (p32, v32) = (m.pos.split_at_mut(mid), m.vel.split_at_mut(mid));
                    let (p64, v64) = (pos.split_at(mid), vel.split_at(mid));
                    par.both(
                        #[inline(always)]
                        || {
                            round_into(p64.0, p32.0);
                            round_into(v64.0, v32.0);
                        },
                        #[inline(always)]
                        || {
                            round_into(p64.1, p32.1);
                            round_into(v64.1, v32.1);
                        },
                    );
                }
                let (p, v, f) = (&m.pos[..], &m.vel[..], &mut m.force[..]);
                match split {
                    Some(split) => forces::spring_forces_split(
                        topo,
                        &m.kernel.rest,
                        material,
                        adjust,
                        p,
                        v,
                        f,
                        split,
                        par.pair,
                        par.isa,
                        stats,
                    ),
                    None => forces::spring_forces(topo, material, adjust, p, v, f, &mut m.kernel, stats),
                }
            }
        };
        if !topo.bending.is_empty() {
            // Bending stencils (a mesh cloth with a bending rigidity), in f64 whatever the springs'
            // precision: few, and linear.
            let b = material.get(SpringClass::BendU);
            totals.elastic_energy += topo.bending.add_forces(b.k, b.c, pos, vel, f);
        }
        self.loads.add_forces(topo, t, pos, vel, f, &mut ws.normals);
        for grab in &self.grabs {
            grab.add_force(pos, vel, f);
        }
        if defer && ws.mixed.is_some() && !self.f64_forces() {
            return (totals, true);
        }
        self.to_accelerations(vel, f, acc, ws.mixed.as_deref_mut(), par);
        (totals, false)
    }

    /// The force-to-acceleration pass: the f64 forces `f` (and the f32
    /// spring forces in `mixed`) at velocity `vel` into `acc`, clearing
    /// both force buffers.
    #[inline(always)]
    fn to_accelerations(&self, vel: &[f64], f: &mut [f64], acc: &mut [f64], mixed: Option<&mut Mixed>, par: Par) {
        let n = self.topology.n_nodes;
        let (g, drag) = (self.params.gravity, self.params.drag);
        let f64_forces = self.f64_forces();
        // Force → acceleration node by node: any split gives the same bits.
        let (inv_mass, free) = (&self.inv_mass[..n], &self.free[..n]);
        let vel = [&vel[..n], &vel[n..2 * n], &vel[2 * n..3 * n]];
        let cut = par.split.unwrap_or(n);
        let (f0, f1) = node_halves_mut(f, n, cut);
        let (a0, a1) = node_halves_mut(acc, n, cut);
        // The f32 spring forces, when there are, added here and cleared.
        let (s0, s1) = match mixed {
            Some(m) => {
                let (s0, s1) = node_halves_mut(&mut m.force, n, cut);
                (s0.map(Some), s1.map(Some))
            }
            None => ([None, None, None], [None, None, None]),
        };
        let convert = inlined(
            #[inline(always)]
            |lo: usize, f: [&mut [f64]; 3], a: [&mut [f64]; 3], s: [Option<&mut [f32]>; 3]| {
                let len = f[0].len();
                let (inv_mass, free) = (&inv_mass[lo..lo + len], &free[lo..lo + len]);
                for (c, ((fc, ac), sc)) in f.into_iter().zip(a).zip(s).enumerate() {
                    let vc = &vel[c][lo..lo + len];
                    let ac = &mut ac[..len];
                    match sc {
                        None => {
                            for k in 0..len {
                                ac[k] = nodes::acceleration(fc[k], inv_mass[k], free[k], g[c], drag, vc[k]);
                                fc[k] = 0.0;
                            }
                        }
                        Some(sc) if f64_forces => {
                            let sc = &mut sc[..len];
                            for k in 0..len {
                                let fk = fc[k] + f64::from(sc[k]);
                                ac[k] = nodes::acceleration(fk, inv_mass[k], free[k], g[c], drag, vc[k]);
                                fc[k] = 0.0;
                                sc[k] = 0.0;
                            }
                        }
                        Some(sc) => {
                            // fc is all +0 here: the same sum without reading it.
                            let sc = &mut sc[..len];
                            for k in 0..len {
                                let fk = 0.0 + f64::from(sc[k]);
                                ac[k] = nodes::acceleration(fk, inv_mass[k], free[k], g[c], drag, vc[k]);
                                sc[k] = 0.0;
                            }
                        }
                    }
                }
            },
        );
        par.both(
            #[inline(always)]
            || convert(0, f0, a0, s0),
            #[inline(always)]
            || convert(cut, f1, a1, s1),
        );
    }
}

/// How a step may split its work: the pair that runs the halves, where the
/// nodes are split (None: the cloth is too small to gain, one piece), and
/// the instruction set the halves are compiled for.
#[derive(Clone, Copy)]
struct Par<'a> {
    pair: &'a dyn Pair,
    split: Option<usize>,
    isa: Isa,
}

impl Par<'_> {
    /// Run `a` and `b` on the pair when split, else both here (already
    /// inside the caller's dispatch).
    #[inline(always)]
    fn both(self, a: impl FnOnce() + Send, b: impl FnOnce() + Send) {
        if self.split.is_none() {
            a();
            b();
            return;
        }
        let isa = self.isa;
        let (mut a, mut b) = (Some(a), Some(b));
        self.pair.join(
            &mut || {
                if let Some(a) = a.take() {
                    simd::run(isa, a)
                }
            },
            &mut || {
                if let Some(b) = b.take() {
                    simd::run(isa, b)
                }
            },
        );
    }

    /// The flat index where elementwise passes over `[x…, y…, z…]` fields of
    /// `len` entries split: the middle, on a cache-line boundary.
    fn flat_mid(self, len: usize) -> usize {
        if self.split.is_some() {
            (len / 2) & !7
        } else {
            len
        }
    }
}

/// The node split of a cloth of `topology`: the middle node, on a
/// cache-line boundary, for cloths large enough that two threads gain;
/// None for smaller ones and for topologies that cannot be split.
fn node_split(topology: &Topology) -> Option<usize> {
    let split = (topology.n_nodes / 2) & !7;
    (topology.n_nodes >= SPLIT_MIN_NODES && forces::can_split(topology, split)).then_some(split)
}

/// Cloths of at least this many nodes step in two halves (see
/// [`Simulation::step_on`]).
pub const SPLIT_MIN_NODES: usize = 8192;

/// The three components of a `[x…, y…, z…]` field of `n` nodes, each cut
/// at node `cut` (`cut == n`: the second pieces are empty).
#[inline(always)]
fn node_halves_mut<T>(field: &mut [T], n: usize, cut: usize) -> ([&mut [T]; 3], [&mut [T]; 3]) {
    let (x, rest) = field.split_at_mut(n);
    let (y, z) = rest.split_at_mut(n);
    let (x0, x1) = x.split_at_mut(cut);
    let (y0, y1) = y.split_at_mut(cut);
    let (z0, z1) = z[..n].split_at_mut(cut);
    ([x0, y0, z0], [x1, y1, z1])
}

/// The fused last pass of a step (see [`nodes`]) over both halves:
/// symplectic Euler's from the acceleration `a` (`b` None), or RK4's from
/// the weighted sums of the stages' accelerations `a` and velocities `b`
/// with `h` = dt/6. Returns the report's sums.
#[inline(always)]
fn fused_last(
    par: Par,
    model: &Model,
    state: &mut State,
    mixed: Option<&mut Mixed>,
    a: Option<&[f64]>,
    b: Option<&[f64]>,
    h: f64,
) -> Sums {
    let n = model.topology.n_nodes;
    let cut = par.split.unwrap_or(n);
    let (x0, x1) = node_halves_mut(&mut state.pos, n, cut);
    let (v0, v1) = node_halves_mut(&mut state.vel, n, cut);
    // Without `a`, symplectic Euler makes the acceleration from the f32
    // spring forces (see `Simulation::pending`).
    let (mixed, forces) = match (a, mixed) {
        (None, Some(m)) => {
            let Mixed { pos, vel, force, .. } = m;
            let (f0, f1) = node_halves_mut(force, n, cut);
            (Some((pos, vel)), Some((f0, f1)))
        }
        (_, m) => (m.map(|m| (&mut m.pos, &mut m.vel)), None),
    };
    let (a0, a1) = match a {
        Some(a) => node_halves(a, n, cut),
        None => ([&[][..]; 3], [&[][..]; 3]),
    };
    let (b0, b1) = match b {
        Some(b) => node_halves(b, n, cut),
        None => ([&[][..]; 3], [&[][..]; 3]),
    };
    let copy = mixed.is_some();
    let ((p0, p1), (q0, q1)) = f32_halves(mixed, n, cut);
    let (mass, free) = (&model.masses[..n], &model.free[..n]);
    let (inv_mass, drag) = (&model.inv_mass[..n], model.params.drag);
    let (r0, r1) = match forces {
        Some((f0, f1)) => (
            Some(nodes::Forces {
                f: f0,
                inv_mass: &inv_mass[..cut],
                drag,
            }),
            Some(nodes::Forces {
                f: f1,
                inv_mass: &inv_mass[cut..],
                drag,
            }),
        ),
        None => (None, None),
    };
    let (lo, hi) = (
        nodes::Piece {
            x: x0,
            v: v0,
            a: a0,
            b: b0,
            x32: p0,
            v32: q0,
            copy,
            mass: &mass[..cut],
            free: &free[..cut],
            forces: r0,
        },
        nodes::Piece {
            x: x1,
            v: v1,
            a: a1,
            b: b1,
            x32: p1,
            v32: q1,
            copy,
            mass: &mass[cut..],
            free: &free[cut..],
            forces: r1,
        },
    );
    let (rk4, g) = (b.is_some(), model.params.gravity);
    let pass = inlined(
        #[inline(always)]
        |piece: nodes::Piece| {
            if rk4 {
                nodes::rk4_last(piece, h, g)
            } else {
                nodes::symplectic(piece, h, g)
            }
        },
    );
    let (mut s0, mut s1) = (NO_SUMS, NO_SUMS);
    par.both(
        #[inline(always)]
        || s0 = pass(lo),
        #[inline(always)]
        || s1 = pass(hi),
    );
    if par.split.is_some() {
        nodes::merge(&mut s0, &s1);
    }
    s0
}

/// [`node_halves_mut`] for reading.
#[inline(always)]
fn node_halves(field: &[f64], n: usize, cut: usize) -> ([&[f64]; 3], [&[f64]; 3]) {
    let (x, rest) = field.split_at(n);
    let (y, z) = rest.split_at(n);
    let (x0, x1) = x.split_at(cut);
    let (y0, y1) = y.split_at(cut);
    let (z0, z1) = z[..n].split_at(cut);
    ([x0, y0, z0], [x1, y1, z1])
}

/// Halves of the f32 copies of positions and velocities (empty slices with
/// f64 springs): ((positions' low, high), (velocities' low, high)).
type F32Halves<'a> = ([&'a mut [f32]; 3], [&'a mut [f32]; 3]);

#[inline(always)]
fn f32_halves<'a>(
    mixed: Option<(&'a mut Paged<f32>, &'a mut Paged<f32>)>,
    n: usize,
    cut: usize,
) -> (F32Halves<'a>, F32Halves<'a>) {
    match mixed {
        Some((pos, vel)) => (node_halves_mut(pos, n, cut), node_halves_mut(vel, n, cut)),
        None => (
            ([&mut [][..], &mut [], &mut []], [&mut [][..], &mut [], &mut []]),
            ([&mut [][..], &mut [], &mut []], [&mut [][..], &mut [], &mut []]),
        ),
    }
}

/// The f32 copies of a stage cut at flat index `mid`, like the flat passes.
#[inline(always)]
fn flat_f32_halves(mixed: Option<&mut Mixed>, mid: usize) -> (nodes::Copies<'_>, nodes::Copies<'_>) {
    match mixed {
        Some(m) => {
            let (p0, p1) = m.pos.split_at_mut(mid);
            let (v0, v1) = m.vel.split_at_mut(mid);
            (Some((p0, v0)), Some((p1, v1)))
        }
        None => (None, None),
    }
}

/// `f` itself: lets a closure bound to a name carry `#[inline(always)]`
/// (attributes are allowed on call arguments, not on `let` initialisers).
#[inline(always)]
fn inlined<F>(f: F) -> F {
    f
}

/// Every slice cut at `mid`.
#[inline(always)]
fn halves<const R: usize>(s: [&[f64]; R], mid: usize) -> ([&[f64]; R], [&[f64]; R]) {
    (s.map(|x| &x[..mid]), s.map(|x| &x[mid..]))
}

/// Every slice cut at `mid`.
#[inline(always)]
fn halves_mut<'a, const W: usize>(s: [&'a mut [f64]; W], mid: usize) -> ([&'a mut [f64]; W], [&'a mut [f64]; W]) {
    let mut highs: [Option<&'a mut [f64]>; W] = [const { None }; W];
    let mut s = s.map(Some);
    let lows = std::array::from_fn(|i| {
        let (lo, hi) = s[i].take().expect("each slice once").split_at_mut(mid);
        highs[i] = Some(hi);
        lo
    });
    (lows, highs.map(|h| h.expect("set with its low half")))
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
    /// forces in `ws.mixed` for symplectic Euler's update, which turns them
    /// into accelerations in its own pass (one pass over the nodes fewer;
    /// see [`Simulation::ensure_cache_from`]). Anything else that reads
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
        let inv_mass = (0..n).map(|k| if pinned[k] { 0.0 } else { 1.0 / masses[k] }).collect();
        let free = (0..n).map(|k| if pinned[k] { 0.0 } else { 1.0 }).collect();
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
            if self.model.params.integrator != Integrator::SymplecticEuler {
                self.flush(par);
            }
        }
        let dt = self.model.params.dt;
        let t0 = self.state.time;
        let mut solver = (0, 0.0);
        // The report sums of a fused last pass (symplectic Euler, RK4).
        let mut fused = None;
        if !self.model.loads.colliders.is_empty() {
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
        // The fused pass's f32 copies and sums describe the final state when
        // nothing but the pins (which write their copies) moved a node since,
        // and every node was finite before the pins (so the pinned nodes'
        // massless terms were exact zeros, as they are now).
        let fused =
            fused.filter(|s: &Sums| pins_finite && strain_iterations == 0 && contacts == 0 && s.finish([0.0; 3]).2);
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
            // Symplectic Euler takes the f32 spring forces as they are.
            let defer = self.model.params.integrator == Integrator::SymplecticEuler;
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
    /// state and the report's sums (returned; see [`nodes`]).
    #[inline(always)]
    fn rk4(&mut self, t0: f64, dt: f64, par: Par) -> Sums {
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
            let (r0, r1) = halves([pos, vel, &self.acc[..len]], mid);
            let (w0, w1) = halves_mut(
                [
                    &mut sum_pos[..len],
                    &mut sum_vel[..len],
                    &mut stage_pos[..len],
                    &mut stage_vel[..len],
                ],
                mid,
            );
            let (c0, c1) = flat_f32_halves(mixed.as_deref_mut(), mid);
            par.both(
                #[inline(always)]
                || nodes::rk4_first(r0, w0, c0, dt),
                #[inline(always)]
                || nodes::rk4_first(r1, w1, c1, dt),
            );
        }
        let mut stage_pos = std::mem::take(stage_pos);
        let mut stage_vel = std::mem::take(stage_vel);
        let mut stage_acc = std::mem::take(stage_acc);
        let n = self.model.topology.n_nodes;
        // k2, k3 at the midpoint, k4 at the end.
        for (weight, t_stage, next_scale) in [(2.0, 0.5 * dt, 0.5 * dt), (2.0, 0.5 * dt, dt), (1.0, dt, 0.0)] {
            // Pinned nodes are where their paths put them at the stage's time:
            // extrapolating them with the start-of-step velocity (their
            // acceleration is 0) made RK4 first order for moving pins
            // (tests/convergence.rs). Fixed pins are unchanged by this.
            for pin in &self.model.loads.pins {
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
            self.model.accelerations(
                t0 + t_stage,
                &stage_pos,
                &stage_vel,
                &mut stage_acc,
                &mut self.ws,
                par,
                rounded,
                false,
                // A stage's figures are never reported.
                false,
            );
            let (r0, r1) = halves([&pos[..len], &vel[..len], &stage_acc[..len]], mid);
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
            let (c0, c1) = if next_scale != 0.0 {
                flat_f32_halves(self.ws.mixed.as_deref_mut(), mid)
            } else {
                (None, None)
            };
            par.both(
                #[inline(always)]
                || nodes::rk4_stage(r0, w0, c0, weight, next_scale),
                #[inline(always)]
                || nodes::rk4_stage(r1, w1, c1, weight, next_scale),
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

    /// The report of the current state. One pass over the nodes gives the
    /// energies and finiteness, with `LANES` partial sums (a sequential sum
    /// is one long chain of dependent additions, several µs at 64×64); a
    /// split step sums each half's lanes and adds the halves lane by lane.
    #[inline(always)]
    fn measure(&self, solver: (u32, f64), strain_iterations: u32, par: Par, stats: bool) -> StepReport {
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
    fn report_of(&self, sums: Sums, solver: (u32, f64), strain_iterations: u32, stats: bool) -> StepReport {
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
        }
    }
}

fn invalid(name: impl Into<String>, value: f64, reason: &'static str) -> SimError {
    SimError::InvalidParameter {
        name: name.into(),
        value,
        reason,
    }
}

fn validate_params(p: &SimParams) -> Result<(), SimError> {
    if !(p.dt.is_finite() && p.dt > 0.0) {
        return Err(invalid("dt", p.dt, "the time step must be positive and finite"));
    }
    for class in SpringClass::ALL {
        let c = p.material.get(class);
        if !(c.k.is_finite() && c.k >= 0.0) {
            return Err(invalid(format!("{class}.k"), c.k, "stiffness must be finite and ≥ 0"));
        }
        if !(c.c.is_finite() && c.c >= 0.0) {
            return Err(invalid(format!("{class}.c"), c.c, "damping must be finite and ≥ 0"));
        }
    }
    if let Some((c, &g)) = p.gravity.iter().enumerate().find(|(_, g)| !g.is_finite()) {
        return Err(invalid(format!("gravity[{c}]"), g, "gravity must be finite"));
    }
    if !(p.drag.is_finite() && p.drag >= 0.0) {
        return Err(invalid("drag", p.drag, "drag must be finite and ≥ 0"));
    }
    if let Some(a) = p.stiffness_adjustment {
        if !(a.allowed.is_finite() && a.allowed >= 0.0) {
            return Err(invalid(
                "stiffness_adjustment.allowed",
                a.allowed,
                "allowed strain must be finite and ≥ 0",
            ));
        }
    }
    if let Some(l) = p.strain_limit {
        if !(l.max_strain.is_finite() && l.max_strain >= 0.0) {
            return Err(invalid(
                "strain_limit.max_strain",
                l.max_strain,
                "maximum strain must be finite and ≥ 0",
            ));
        }
        if !(l.tolerance.is_finite() && l.tolerance >= 0.0) {
            return Err(invalid(
                "strain_limit.tolerance",
                l.tolerance,
                "tolerance must be finite and ≥ 0",
            ));
        }
    }
    if !(p.cg.tolerance.is_finite() && p.cg.tolerance > 0.0) {
        return Err(invalid("cg.tolerance", p.cg.tolerance, "CG tolerance must be positive"));
    }
    if p.cg.max_iterations == 0 {
        return Err(invalid("cg.max_iterations", 0.0, "CG needs at least one iteration"));
    }
    Ok(())
}

/// A node set with one share each (`shares` names the shares, `what` the
/// set in errors), every node in a cloth of `n` nodes.
fn check_node_shares(
    nodes: &[u32],
    shares: &[f64],
    n: usize,
    what: &'static str,
    shares_what: &'static str,
) -> Result<(), SimError> {
    if nodes.len() != shares.len() {
        return Err(SimError::SizeMismatch {
            what: shares_what,
            got: shares.len(),
            expected: nodes.len(),
        });
    }
    if let Some(&k) = nodes.iter().find(|&&k| k as usize >= n) {
        return Err(SimError::NodeOutOfRange {
            what,
            node: k,
            n_nodes: n,
        });
    }
    Ok(())
}

fn validate_loads(loads: &Loads, n: usize) -> Result<(), SimError> {
    for (i, load) in loads.forces.iter().enumerate() {
        check_node_shares(&load.nodes, &load.shares, n, "force", "load shares")?;
        if let Some(&f) = load.force.iter().chain(&load.shares).find(|f| !f.is_finite()) {
            return Err(invalid(
                format!("forces[{i}]"),
                f,
                "force components and shares must be finite",
            ));
        }
    }
    if let Some(w) = &loads.wind {
        let all = w.velocity.iter().chain([&w.air_density, &w.drag_coefficient]);
        if let Some(&x) = all.clone().find(|x| !x.is_finite()) {
            return Err(invalid("wind", x, "wind values must be finite"));
        }
        if w.air_density < 0.0 || w.drag_coefficient < 0.0 {
            return Err(invalid(
                "wind",
                w.air_density.min(w.drag_coefficient),
                "air density and drag coefficient must be ≥ 0",
            ));
        }
    }
    for (i, t) in loads.tethers.iter().enumerate() {
        if t.node as usize >= n {
            return Err(SimError::NodeOutOfRange {
                what: "tether",
                node: t.node,
                n_nodes: n,
            });
        }
        if let Some(&x) = t
            .target
            .iter()
            .chain([&t.stiffness, &t.damping])
            .find(|x| !x.is_finite())
        {
            return Err(invalid(
                format!("tethers[{i}]"),
                x,
                "tether target, stiffness and damping must be finite",
            ));
        }
        if t.stiffness < 0.0 || t.damping < 0.0 {
            return Err(invalid(
                format!("tethers[{i}]"),
                t.stiffness.min(t.damping),
                "tether stiffness and damping must be ≥ 0",
            ));
        }
    }
    for (i, body) in loads.colliders.iter().enumerate() {
        validate_collider(i, body)?;
    }
    for pin in &loads.pins {
        if pin.node as usize >= n {
            return Err(SimError::NodeOutOfRange {
                what: "pin",
                node: pin.node,
                n_nodes: n,
            });
        }
        if pin.anchor.iter().any(|x| !x.is_finite()) {
            return Err(invalid(
                format!("pin on node {}", pin.node),
                f64::NAN,
                "pin anchor must be finite",
            ));
        }
    }
    Ok(())
}

fn validate_collider(i: usize, body: &Collider) -> Result<(), SimError> {
    let name = |what: &str| format!("colliders[{i}].{what}");
    let speed = match body.path {
        PinPath::Fixed => 0.0,
        PinPath::Linear { velocity, .. } => vec3::norm(velocity),
        PinPath::Sine { amplitude, frequency } => vec3::norm(amplitude) * frequency,
    };
    let checks: [(&str, f64, bool, &'static str); 4] = [
        ("position", vec3::norm(body.position), true, "must be finite"),
        ("path", speed, true, "must be finite"),
        (
            "friction",
            body.friction,
            body.friction >= 0.0,
            "must be finite and ≥ 0",
        ),
        (
            "clearance",
            body.clearance,
            body.clearance >= 0.0,
            "must be finite and ≥ 0",
        ),
    ];
    for (what, x, ok, reason) in checks {
        if !(x.is_finite() && ok) {
            return Err(invalid(name(what), x, reason));
        }
    }
    match body.shape {
        Shape::Plane { normal } => {
            if !((vec3::norm(normal) - 1.0).abs() < 1e-9) {
                return Err(invalid(
                    name("normal"),
                    vec3::norm(normal),
                    "a plane's normal must be a unit vector",
                ));
            }
        }
        Shape::Sphere { radius } | Shape::Capsule { radius, .. } => {
            if !(radius.is_finite() && radius > 0.0) {
                return Err(invalid(name("radius"), radius, "must be finite and > 0"));
            }
            if let Shape::Capsule { half_axis, .. } = body.shape {
                if !vec3::norm(half_axis).is_finite() {
                    return Err(invalid(name("half_axis"), vec3::norm(half_axis), "must be finite"));
                }
            }
        }
        Shape::Cuboid { half_extents } => {
            if let Some(&e) = half_extents.iter().find(|e| !(e.is_finite() && **e > 0.0)) {
                return Err(invalid(name("half_extents"), e, "each must be finite and > 0"));
            }
        }
        Shape::Cylinder { radius, half_height } => {
            for (field, x) in [("radius", radius), ("half_height", half_height)] {
                if !(x.is_finite() && x > 0.0) {
                    return Err(invalid(name(field), x, "must be finite and > 0"));
                }
            }
        }
    }
    Ok(())
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
