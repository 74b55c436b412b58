//! What every force evaluation reads and writes: the model (topology,
//! masses, parameters, loads, live grabs and pin moves), the workspace of
//! preallocated buffers, the f32 copies of a step with f32 springs, and the
//! evaluation itself (springs, bending, loads, then accelerations).

use std::sync::Arc;

use super::forces::{self, KernelScratch, SpringTotals};
use super::implicit::ImplicitWorkspace;
use super::nodes;
use super::paged::Paged;
use super::par::{inlined, node_halves_mut, Par};
use super::params::{Integrator, SimParams, SpringClass};
use super::strain::StrainWorkspace;
use super::xpbd::XpbdWorkspace;
use super::{Assembled, Grab, Loads, PinShift, Topology};

/// Scratch buffers; allocated once when the simulation is built.
#[derive(Debug, Clone)]
pub(super) struct Workspace {
    pub(super) kernel: KernelScratch<f64>,
    /// Zero between evaluations; each evaluation uses a window of it placed
    /// away from the positions and velocities it reads (see [`paged`]).
    pub(super) force: Paged,
    pub(super) normals: Vec<f64>,
    /// RK4: stage position/velocity, accumulated increments, stage
    /// acceleration; each at its own page offset (see [`paged`]).
    pub(super) stage_pos: Paged,
    pub(super) stage_vel: Paged,
    pub(super) sum_pos: Paged,
    pub(super) sum_vel: Paged,
    pub(super) stage_acc: Paged,
    pub(super) implicit: Option<ImplicitWorkspace>,
    pub(super) strain: Option<StrainWorkspace>,
    /// Positions at the start of the step, for contact's swept test, and
    /// contact's marks, one per node (both empty without colliders).
    pub(super) before: Vec<f64>,
    pub(super) near: Vec<u8>,
    /// Springs in f32 ([`SpringPrecision::F32`]); None in f64.
    pub(super) mixed: Option<Box<Mixed>>,
    /// XPBD's sweep order and buffers (XPBD only).
    pub(super) xpbd: Option<Box<XpbdWorkspace>>,
    /// Self-contact's grids and buffers (with self-contact only).
    pub(super) selfc: Option<Box<super::selfcontact::SelfWorkspace>>,
}

/// The f32 side of a step with [`SpringPrecision::F32`]: positions and
/// velocities rounded for the kernel, and its forces (zero between
/// evaluations, like [`Workspace::force`]).
#[derive(Debug, Clone)]
pub(super) struct Mixed {
    pub(super) pos: Paged<f32>,
    pub(super) vel: Paged<f32>,
    pub(super) force: Paged<f32>,
    pub(super) kernel: KernelScratch<f32>,
    /// The bending stencils' operator assembled (`None` without stencils):
    /// the fast path's bending, in f64 like the stencils.
    pub(super) bending: Option<Assembled>,
    /// Its scratch: one entry per node.
    pub(super) bending_scratch: Vec<[f64; 4]>,
}

impl Mixed {
    /// Each buffer a third of a page from the others: at 64×64 every f32
    /// component array is 16 KiB, so the nine streams of the kernel would
    /// otherwise share one L1 set (see [`paged`]); measured 45 µs a 64²
    /// symplectic step with plain allocations against 36 placed. The first
    /// step moves them away from the state too (`Simulation::place_buffers`).
    pub(super) fn new(topology: &Topology) -> Mixed {
        let n3 = 3 * topology.n_nodes;
        Mixed {
            pos: Paged::new(n3, 0),
            vel: Paged::new(n3, 1344),
            force: Paged::new(n3, 2688),
            kernel: KernelScratch::new(topology),
            bending: (!topology.bending.is_empty()).then(|| topology.bending.assembled(topology.n_nodes)),
            bending_scratch: vec![
                [0.0; 4];
                if topology.bending.is_empty() {
                    0
                } else {
                    topology.n_nodes
                }
            ],
        }
    }
}

/// `dst[i] = src[i]` rounded to f32 (to nearest, ties to even: the same on
/// every instruction set).
#[inline(always)]
pub(super) fn round_into(src: &[f64], dst: &mut [f32]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s as f32;
    }
}

/// Page offset of the `i`th field buffer the integrators stream through
/// together (RK4's five and the acceleration): ten cache lines apart.
pub(super) fn colour(i: usize) -> usize {
    i * 640
}

impl Workspace {
    pub(super) fn new(topology: &Topology, params: &SimParams, loads: &Loads) -> Workspace {
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
            before: if loads.colliders.is_empty() && params.self_contact.is_none() {
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
            selfc: params
                .self_contact
                .map(|c| Box::new(super::selfcontact::SelfWorkspace::new(topology, &c))),
        }
    }
}

/// Read-only model data shared by every force evaluation.
#[derive(Debug, Clone)]
pub(super) struct Model {
    pub(super) topology: Arc<Topology>,
    pub(super) masses: Paged,
    /// 1/m for free nodes, 0 for pinned ones.
    pub(super) inv_mass: Paged,
    /// 1 for free nodes, 0 for pinned ones.
    pub(super) free: Paged,
    pub(super) params: SimParams,
    pub(super) loads: Loads,
    /// Live grabs (see [`Simulation::set_grabs`]).
    pub(super) grabs: Vec<Grab>,
    /// Live pin moves, one per entry of `loads.pins` (empty when none was
    /// ever moved; see [`Simulation::shift_pins`]).
    pub(super) pin_shifts: Vec<PinShift>,
}

impl Model {
    pub(super) fn adjust_ratio(&self) -> f64 {
        self.params
            .stiffness_adjustment
            .map_or(f64::INFINITY, |a| 1.0 + a.allowed)
    }

    /// Every force but the springs' and the bending stencils' at (t, pos,
    /// vel) into `out`: loads, wind, grabs, gravity and drag; zero on pinned
    /// nodes.
    pub(super) fn external_forces(&self, t: f64, pos: &[f64], vel: &[f64], out: &mut [f64], normals: &mut [f64]) {
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
    pub(super) fn f64_forces(&self) -> bool {
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
    pub(super) fn accelerations(
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
            // precision: few, and linear. With f32 springs (the live level's fast path) through
            // their assembled operator: the same forces up to rounding, cheaper (`Assembled`).
            let b = material.get(SpringClass::BendU);
            totals.elastic_energy += match ws.mixed.as_deref_mut() {
                Some(Mixed {
                    bending: Some(op),
                    bending_scratch,
                    ..
                }) => op.add_forces(b.k, b.c, (pos, vel), f, bending_scratch, stats),
                _ => topo.bending.add_forces(b.k, b.c, pos, vel, f),
            };
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
    pub(super) fn to_accelerations(
        &self,
        vel: &[f64],
        f: &mut [f64],
        acc: &mut [f64],
        mixed: Option<&mut Mixed>,
        par: Par,
    ) {
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
