//! Inverse Hooke's-law estimation (Sung 2018 §5.1) and our global
//! least-squares fit, from observations of the reference mapped onto the
//! coarse cloth.
//!
//! # Observations
//! For every estimation sample, the reference positions at steps n−1, n, n+1
//! are mapped onto the coarse nodes ([`Correlation`]). The coarse node's
//! velocity and acceleration follow by finite differences:
//! `a = (x₊ − 2x + x₋)/dt²`; `v = (x − x₋)/dt` when the reference ran
//! symplectic Euler (then `m·a = F(x, v)` holds *exactly* for the reference's
//! own springs, which makes synthetic recovery exact) and `v = (x₊ − x₋)/2dt`
//! otherwise (second order). The spring force a coarse node must feel to
//! follow the reference is `F_spring = m·a − F_ext` with `F_ext` = scene
//! loads, wind, gravity and drag of the coarse cloth
//! ([`Simulation::external_forces`]). Pinned nodes carry no information,
//! nor, in a sample, do nodes near a collider (their acceleration holds an
//! unknown contact force; [`Observation::touching`]).
//!
//! # Per-class bases
//! Eq. 1 is linear in the coefficients: the spring force on node i is
//! `Σ_t K_t·G_t,i + C_t·H_t,i` with `G_t,i = Σ (L − L0)·u` (unit stiffness)
//! and `H_t,i = Σ ((v_j − v_i)·u)·u` (unit damping) over node i's springs of
//! class t. Classes are the paper's three types split by grid direction
//! ([`SpringClass`]: structural and bend along u and along v, shear), so
//! every method below estimates per-direction coefficients.
//!
//! # BCD and GKD (the paper's methods, as we read them)
//! The published text lost its equations; our first reading, kept
//! deliberately close to the prose (now `totals_ratios`; the default is
//! another, see "Readings" below):
//! 1. Shares: at every reference node j, `S_t,j = |F_t,j| / Σ_s |F_s,j|`,
//!    with `F_t,j` the type-t spring force from the reference coefficients.
//!    **BCD**: a coarse node's shares are the barycentric blend of the shares
//!    of its triangle's three nodes. **GKD**: `R_t = Σ_j w_j |F_t,j| / Σ_j w_j
//!    Σ_s |F_s,j|` over reference nodes within 1.25× the coarse shear-spring
//!    length, `w_j` from a 7-cell Gaussian kernel with σ = 3.0 cells spanning
//!    that radius (cell `c = round(3·d/r)`, `w = exp(−c²/2σ²)`).
//! 2. `F_t = R_t · F_spring` (eq. 3/6).
//! 3. Eq. 7, stiffness ignoring damping: `K_t = F_t·G_t / |G_t|²` (the vector
//!    form of `K = F/(L − L0)`); eq. 8, damping from the remainder with that
//!    K: `C_t = (F_t − K_t·G_t)·H_t / |H_t|²`.
//! 4. Per type, the averages of the accepted per-node, per-sample values.
//!
//! # Readings of the lost equations ([`Reading`])
//! The prose admits other readings; each is selectable and
//! `lodcloth-lab readings` scores them all against the paper's
//! Table 1 trend (docs/readings.md). The default, `reference_lsq`, is the
//! one closest to it. Three choices, each with the reading above first:
//! - **shares** from the *type totals* `|F_t,j|` (springs of a type on
//!   opposite sides of a node cancel) or from the *spring magnitudes*
//!   `Σ_{s∈t,j} |f_s|` (every spring's own force, no cancellation);
//! - **force** per type at the coarse node: the *observed* `R_t·F_spring`
//!   (step 2), or the *reference's* own type-t spring forces carried to the
//!   coarse node (`m_k·Σ w_j F_t,j / Σ w_j m_j` with the BCD or GKD weights;
//!   no shares, no observed acceleration);
//! - **averaging**: the mean of per-node, per-sample *ratios* (step 4), or
//!   one *least-squares* ratio per type over every node and sample
//!   (`K_t = Σ F_t·G_t / Σ |G_t|²`, then `C_t = Σ (F_t − K_t G_t)·H_t /
//!   Σ |H_t|²`): eqs. 7–8 solved for the whole run at once, so nodes near
//!   rest weigh little instead of being rejected.
//!
//! Rejected samples, counted per type and reason: springs near rest length
//! (`|G_t|` below 1e-4 of the type's rest length: K is noise over ~0), no
//! relative velocity (`|H_t|` below 1e-4 m/s: C undefined), and negative
//! estimates (a spring force opposite to the elongation). A class with no
//! accepted sample keeps the level's `same` coefficient, and the report says so.
//!
//! # Mesh levels: stretch held at the material's
//! On a mesh level ([`Topology::mesh`]) BCD, GKD and `lsq` keep the stretch
//! springs' K and C at the prior's (the level's `same`, the membrane's
//! stretch made exactly on that level's triangles, `mesh/springs.rs`) and
//! estimate the rest ([`stretch_held`]). A coarse mesh edge spans
//! several reference edges, and where the reference folds finer than the
//! level resolves, the coarse chord through the mapped reference is shorter
//! than the material along it: the chord reads compression where the
//! material is in tension, so `F·G` has no stretch in it. Measured
//! (`examples/inverse_diag.rs`, 1 s of each reference): on the skirt at
//! 915 of 2,288 vertices the mapped coarse edges averaged −1.5 % strain
//! (a tenth of them beyond −4.7 %) while the reference's own edges
//! averaged +0.08 %; on a 344-vertex sheet at 206 vertices +0.003 %
//! against +0.09 %. The stretch ratios were then noise, and BCD's K came
//! out at 1/900 of the membrane's on that sheet (predicted error 38.8 %
//! against `same`'s 1.1 %; `lsq` 63.8 %). Held, the same runs give 1.15 %
//! and 1.17 %, and on the skirt `lsq` 7.5 % against `same`'s 9.3 %. A grid
//! level keeps estimating every class: its coarse nodes are not reference
//! nodes, its chords see less folding, and Table 1 is measured that way.
//!
//! # `lsq` (ours)
//! One least-squares fit of the ten coefficients to every free node, sample
//! and component at once: `min |A·q − b|² + λ·s·|q − 1|²` where `q` are the
//! coefficients relative to the level's `same` (so columns are comparably
//! scaled), `s = tr(AᵀA)/10` and λ = 1e-9 (a whisper of ridge that only acts
//! in directions the data does not determine). The report gives the
//! condition number of the column-equilibrated normal matrix and the
//! relative residual. Non-positive solutions are not allowed: the offending
//! coefficient is fixed at 1e-3× the reference and the rest re-solved
//! (reported as `clamped`). On a mesh level the stretch K and C are held at
//! the prior's and the rest solved around them (reported as `held`).

use nalgebra::{SMatrix, SVector};

use super::reference::Reference;
use super::{Progress, ProgressFn};
use crate::lod::Correlation;
use crate::sim::vec3::dot;
use crate::sim::{Integrator, Material, Simulation, SpringClass, SpringCoeffs, Topology};

/// Spring classes ([`SpringClass`]): structural u, v, shear, bend u, v.
const T: usize = 5;
/// Coefficients estimated: K then C per class.
const P: usize = 2 * T;

type MatP = SMatrix<f64, P, P>;
type VecP = SVector<f64, P>;

/// Spring forces per class with unit coefficients, SoA per class.
#[derive(Debug, Clone)]
pub struct Bases {
    /// `G_t`: Σ (L − L0)·u over class-t springs, per node (SoA, 3n).
    pub elastic: [Vec<f64>; T],
    /// `H_t`: Σ ((v_j − v_i)·u)·u over class-t springs, per node (SoA, 3n).
    pub damping: [Vec<f64>; T],
}

impl Bases {
    /// Zeroed bases for `n` nodes.
    pub fn new(n: usize) -> Bases {
        let z = || std::array::from_fn(|_| vec![0.0; 3 * n]);
        Bases {
            elastic: z(),
            damping: z(),
        }
    }

    /// Evaluate at (pos, vel) on `topology`.
    pub fn compute(&mut self, topology: &Topology, pos: &[f64], vel: &[f64]) {
        let n = topology.n_nodes;
        for t in 0..T {
            self.elastic[t].fill(0.0);
            self.damping[t].fill(0.0);
        }
        for g in &topology.groups {
            let t = g.class.index();
            let (ge, gd) = (&mut self.elastic[t], &mut self.damping[t]);
            for s in 0..g.len() {
                let (a, b) = (g.a[s] as usize, g.b[s] as usize);
                let d = [
                    pos[b] - pos[a],
                    pos[n + b] - pos[n + a],
                    pos[2 * n + b] - pos[2 * n + a],
                ];
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                if len < 1e-12 {
                    continue;
                }
                let u = d.map(|x| x / len);
                let dv = [
                    vel[b] - vel[a],
                    vel[n + b] - vel[n + a],
                    vel[2 * n + b] - vel[2 * n + a],
                ];
                let stretch = len - g.rest[s];
                let rate = dv[0] * u[0] + dv[1] * u[1] + dv[2] * u[2];
                for c in 0..3 {
                    ge[c * n + a] += stretch * u[c];
                    ge[c * n + b] -= stretch * u[c];
                    gd[c * n + a] += rate * u[c];
                    gd[c * n + b] -= rate * u[c];
                }
            }
        }
        // Bending stencils (a mesh cloth with a bending rigidity) are the bend class: unit D gives
        // −WᵀW·x, unit C −WᵀW·v.
        let bend = SpringClass::BendU.index();
        topology.bending.add_product(-1.0, pos, &mut self.elastic[bend]);
        topology.bending.add_product(-1.0, vel, &mut self.damping[bend]);
    }

    /// Class-t force on node k for coefficients (K, C): `K·G + C·H`.
    fn force(&self, t: usize, n: usize, k: usize, co: SpringCoeffs) -> [f64; 3] {
        [0, 1, 2].map(|c| co.k * self.elastic[t][c * n + k] + co.c * self.damping[t][c * n + k])
    }
}

/// One coarse observation: mapped state and the spring force it implies.
#[derive(Debug, Clone)]
pub struct Observation {
    /// Time (s).
    pub time: f64,
    /// Coarse positions and velocities (SoA).
    pub pos: Vec<f64>,
    /// Coarse velocities (SoA).
    pub vel: Vec<f64>,
    /// `m·a − F_ext` per coarse node (SoA; 0 at pinned nodes).
    pub spring_force: Vec<f64>,
    /// Reference (fine) velocities, for the share computations of BCD/GKD.
    pub fine_vel: Vec<f64>,
    /// Index of the reference sample.
    pub sample: usize,
    /// Per coarse node: near a collider at one of the sample's three frames,
    /// so its observed acceleration carries an unknown contact force (empty
    /// when the scene has no colliders).
    pub touching: Vec<bool>,
}

impl Observation {
    /// Whether node `k`'s observed `spring_force` is the springs' alone.
    pub fn springs_alone(&self, k: usize) -> bool {
        !self.touching.get(k).copied().unwrap_or(false)
    }
}

/// Every observation of one coarse level, and which of its nodes are free
/// (pinned nodes carry no information about the springs).
#[derive(Debug, Clone)]
pub struct Observations {
    /// Per coarse node: not pinned.
    pub free: Vec<bool>,
    /// Coarse node masses (kg).
    pub masses: Vec<f64>,
    /// One observation per reference sample.
    pub samples: Vec<Observation>,
}

/// Map the reference's estimation samples onto `coarse` (a simulation of the
/// coarse cloth with the masses and loads to estimate for; its coefficients
/// are not used).
pub fn observe(
    reference: &Reference,
    correlation: &Correlation,
    coarse: &mut Simulation,
    progress: ProgressFn<'_>,
) -> Observations {
    let n = coarse.topology().n_nodes;
    let nf = reference.topology.n_nodes;
    let dt = reference.dt * reference.spec.difference_span as f64;
    let backward = reference.integrator == Integrator::SymplecticEuler && reference.spec.difference_span == 1;
    let masses = coarse.masses().to_vec();
    let mut prev = vec![0.0; 3 * n];
    let mut next = vec![0.0; 3 * n];
    let mut ext = vec![0.0; 3 * n];
    let free: Vec<bool> = pinned_mask(coarse).iter().map(|p| !p).collect();
    let mut out = Vec::with_capacity(reference.samples.len());
    let total = reference.samples.len() as u64;
    for (si, s) in reference.samples.iter().enumerate() {
        let mut pos = vec![0.0; 3 * n];
        correlation.map(&s.prev, &mut prev);
        correlation.map(&s.cur, &mut pos);
        correlation.map(&s.next, &mut next);
        let vel: Vec<f64> = (0..3 * n)
            .map(|i| {
                if backward {
                    (pos[i] - prev[i]) / dt
                } else {
                    (next[i] - prev[i]) / (2.0 * dt)
                }
            })
            .collect();
        let fine_vel: Vec<f64> = (0..3 * nf)
            .map(|i| {
                if backward {
                    (s.cur[i] - s.prev[i]) / dt
                } else {
                    (s.next[i] - s.prev[i]) / (2.0 * dt)
                }
            })
            .collect();
        coarse.external_forces(s.time, &pos, &vel, &mut ext);
        let touching = touching(coarse, dt, s.time, [&prev, &pos, &next]);
        let mut spring_force = vec![0.0; 3 * n];
        for c in 0..3 {
            for k in 0..n {
                let i = c * n + k;
                if free[k] {
                    let acc = (next[i] - 2.0 * pos[i] + prev[i]) / (dt * dt);
                    spring_force[i] = masses[k] * acc - ext[i];
                }
            }
        }
        out.push(Observation {
            time: s.time,
            pos,
            vel,
            spring_force,
            fine_vel,
            sample: si,
            touching,
        });
        progress(Progress {
            stage: "observe",
            done: si as u64 + 1,
            total,
        });
    }
    Observations {
        free,
        masses,
        samples: out,
    }
}

/// Which coarse nodes are near a collider at any of a sample's three
/// mapped frames (`frames` at t − dt, t, t + dt): within the body's
/// clearance plus one coarse cell, since a mapped position blends reference
/// nodes up to a cell away, any of which may be pressed against the body.
/// Empty without colliders.
fn touching(coarse: &Simulation, dt: f64, t: f64, frames: [&[f64]; 3]) -> Vec<bool> {
    let colliders = &coarse.loads().colliders;
    if colliders.is_empty() {
        return Vec::new();
    }
    let topo = coarse.topology();
    let n = topo.n_nodes;
    // A grid's cell, or a mesh's longest edge.
    let cell = topo.grid.map_or_else(
        || {
            topo.groups
                .iter()
                .filter(|g| g.kind() == crate::sim::SpringKind::Structural)
                .flat_map(|g| g.rest.iter().copied())
                .fold(0.0, f64::max)
        },
        |g| g.hx().max(g.hy()),
    );
    (0..n)
        .map(|k| {
            frames.iter().zip([t - dt, t, t + dt]).any(|(x, time)| {
                let p = [x[k], x[n + k], x[2 * n + k]];
                colliders.iter().any(|b| b.distance(p, time) < b.clearance + cell)
            })
        })
        .collect()
}

fn pinned_mask(sim: &Simulation) -> Vec<bool> {
    let mut pinned = vec![false; sim.topology().n_nodes];
    for p in &sim.loads().pins {
        pinned[p.node as usize] = true;
    }
    pinned
}

/// Why inverse samples were rejected, per spring class
/// ([`SpringClass::index`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Rejections {
    /// Node-samples considered per class.
    pub considered: [u64; T],
    /// `|G_t|` too small: springs near rest length (K and C both skipped).
    pub near_rest: [u64; T],
    /// `|H_t|` too small: no relative velocity (C skipped).
    pub no_relative_velocity: [u64; T],
    /// K estimate ≤ 0 (with a least-squares [`Reading`]: 1 when the
    /// class's one ratio came out non-positive).
    pub negative_k: [u64; T],
    /// C estimate < 0.
    pub negative_c: [u64; T],
    /// Accepted K and C values per class.
    pub accepted_k: [u64; T],
    /// See `accepted_k`.
    pub accepted_c: [u64; T],
}

/// Share distribution of the paper's inverse methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Distribution {
    /// Barycentric Coordinate-based Distribution (eq. 3).
    Bcd,
    /// Gaussian Kernel-based Distribution (eqs. 4–6).
    Gkd,
}

/// How BCD and GKD read the paper's lost equations 3–8 (module docs,
/// "Readings"): where the shares come from, which force is split, and how
/// per-sample values become one coefficient.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reading {
    /// Shares from type totals, observed force, mean of ratios (our first
    /// reading, the module docs' steps 1–4).
    TotalsRatios,
    /// Shares from every spring's own force magnitude, observed force, mean
    /// of ratios.
    SpringsRatios,
    /// Shares from type totals, observed force, one least-squares ratio.
    TotalsLsq,
    /// Shares from spring magnitudes, observed force, least squares.
    SpringsLsq,
    /// The reference's type forces carried over, mean of ratios.
    ReferenceRatios,
    /// The reference's type forces carried over, least squares (the
    /// default).
    ReferenceLsq,
}

impl Reading {
    /// The reading BCD and GKD use unless told otherwise: the one closest
    /// to the paper's Table 1 trend (`lodcloth-lab readings`,
    /// docs/readings.md: the paper's order same > BCD > GKD at 3 of its 6
    /// levels, each half of it at 4, BCD/same and GKD/BCD nearest its
    /// ratios; the first reading, kept as `totals_ratios`, at none).
    pub const DEFAULT: Reading = Reading::ReferenceLsq;

    /// Every reading.
    pub const ALL: [Reading; 6] = [
        Reading::TotalsRatios,
        Reading::SpringsRatios,
        Reading::TotalsLsq,
        Reading::SpringsLsq,
        Reading::ReferenceRatios,
        Reading::ReferenceLsq,
    ];

    /// Name on the command line, in CSV and in cache keys.
    pub const fn name(self) -> &'static str {
        match self {
            Reading::TotalsRatios => "totals_ratios",
            Reading::SpringsRatios => "springs_ratios",
            Reading::TotalsLsq => "totals_lsq",
            Reading::SpringsLsq => "springs_lsq",
            Reading::ReferenceRatios => "reference_ratios",
            Reading::ReferenceLsq => "reference_lsq",
        }
    }

    fn spring_shares(self) -> bool {
        matches!(self, Reading::SpringsRatios | Reading::SpringsLsq)
    }

    fn reference_forces(self) -> bool {
        matches!(self, Reading::ReferenceRatios | Reading::ReferenceLsq)
    }

    fn least_squares(self) -> bool {
        matches!(self, Reading::TotalsLsq | Reading::SpringsLsq | Reading::ReferenceLsq)
    }
}

impl Default for Reading {
    fn default() -> Reading {
        Reading::DEFAULT
    }
}

impl crate::names::Named for Reading {
    const ALL: &'static [Reading] = &Reading::ALL;
    fn name(self) -> &'static str {
        Reading::name(self)
    }
}

impl std::fmt::Display for Reading {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Per-class force magnitudes of every spring at each node (SoA per class,
/// one value per node): `Σ |K_t (L − L0) + C_t (Δv·u)|` over the node's
/// class-t springs.
fn spring_magnitudes(topology: &Topology, material: &Material, pos: &[f64], vel: &[f64], out: &mut [Vec<f64>; T]) {
    let n = topology.n_nodes;
    for m in out.iter_mut() {
        m.fill(0.0);
    }
    for g in &topology.groups {
        let t = g.class.index();
        let co = material.springs[t];
        for s in 0..g.len() {
            let (a, b) = (g.a[s] as usize, g.b[s] as usize);
            let d = [0, 1, 2].map(|c| pos[c * n + b] - pos[c * n + a]);
            let len = dot(d, d).sqrt();
            if len < 1e-12 {
                continue;
            }
            let u = d.map(|x| x / len);
            let dv = [0, 1, 2].map(|c| vel[c * n + b] - vel[c * n + a]);
            let f = (co.k * (len - g.rest[s]) + co.c * dot(dv, u)).abs();
            out[t][a] += f;
            out[t][b] += f;
        }
    }
    // A bending stencil's force on each of its nodes: |w_si|·|D·(Wx)_s + C·(Wv)_s|.
    let bending = &topology.bending;
    let co = material.get(SpringClass::BendU);
    for s in 0..bending.len() {
        let (x, v) = (bending.value(s, pos), bending.value(s, vel));
        let g = [0, 1, 2].map(|c| co.k * x[c] + co.c * v[c]);
        let g = dot(g, g).sqrt();
        let (nodes, weights) = bending.row(s);
        for (&i, w) in nodes.iter().zip(weights) {
            out[SpringClass::BendU.index()][i as usize] += w.abs() * g;
        }
    }
}

/// Result of BCD/GKD.
#[derive(Debug, Clone, PartialEq)]
pub struct InverseEstimate {
    /// The estimated coefficients.
    pub material: Material,
    /// Samples rejected, by reason and spring class.
    pub rejections: Rejections,
    /// Classes that had no accepted K (or C) sample and kept the prior's
    /// value (the level's `same`); a class the level has no spring of is
    /// neither sampled nor a fallback.
    pub fallback_k: [bool; T],
    /// See `fallback_k`.
    pub fallback_c: [bool; T],
    /// Classes not estimated by design, K and C kept at the prior's
    /// ([`stretch_held`]: a mesh level's stretch).
    pub held: [bool; T],
}

/// The spring classes whose coefficients the inverse fits keep at the
/// prior's on `coarse` (module docs, "Mesh levels"): the stretch classes
/// of a mesh level; none on a grid.
pub fn stretch_held(coarse: &Topology) -> [bool; T] {
    std::array::from_fn(|t| coarse.mesh.is_some() && SpringClass::ALL[t].kind() == crate::sim::SpringKind::Structural)
}

/// Reference nodes and Gaussian weights around each coarse node (GKD).
fn gkd_neighbourhoods(reference: &Topology, coarse: &Topology) -> Vec<Vec<(u32, f64)>> {
    // The coarse shear-spring length: a grid cell's diagonal; on a surface
    // (no shear springs, irregular rings) √2 × the mean stretch spring.
    let diagonal = match coarse.grid {
        Some(shape) => shape.hx().hypot(shape.hy()),
        None => std::f64::consts::SQRT_2 * mean_rest_lengths(coarse)[SpringClass::StructuralU.index()],
    };
    let radius = 1.25 * diagonal;
    let sigma: f64 = 3.0;
    coarse
        .rest_positions
        .iter()
        .map(|p| {
            let mut list = Vec::new();
            for (j, q) in reference.rest_positions.iter().enumerate() {
                let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                if d <= radius {
                    let cell = (3.0 * d / radius).round();
                    list.push((j as u32, (-cell * cell / (2.0 * sigma * sigma)).exp()));
                }
            }
            list
        })
        .collect()
}

/// Per-class sums of one least-squares reading (eqs. 7–8 over the whole run).
#[derive(Debug, Clone, Copy, Default)]
struct LsqSums {
    fg: f64,
    gg: f64,
    fh: f64,
    gh: f64,
    hh: f64,
}

/// The paper's BCD or GKD estimate from observations, read as `reading`
/// says (module docs); a class with no accepted sample keeps `prior`'s
/// coefficient.
#[allow(clippy::too_many_arguments)]
pub fn inverse_estimate(
    prior: &Material,
    reference: &Reference,
    correlation: &Correlation,
    coarse: &Topology,
    observations: &Observations,
    distribution: Distribution,
    reading: Reading,
    progress: ProgressFn<'_>,
) -> InverseEstimate {
    let n = coarse.n_nodes;
    let nf = reference.topology.n_nodes;
    let rest_len = mean_rest_lengths(coarse);
    // The fine nodes each coarse node draws on, with their weights.
    let weights: Vec<Vec<(u32, f64)>> = match distribution {
        Distribution::Gkd => gkd_neighbourhoods(&reference.topology, coarse),
        Distribution::Bcd => correlation
            .entries()
            .iter()
            .map(|e| e.nodes.iter().zip(&e.weights).map(|(&j, &w)| (j, w)).collect())
            .collect(),
    };
    let held = stretch_held(coarse);
    // Classes the level has no spring of (a mesh's shear and v classes)
    // carry nothing to estimate: neither samples nor fallbacks.
    let present: [bool; T] = std::array::from_fn(|t| {
        coarse.groups.iter().any(|g| g.class.index() == t && !g.is_empty())
            || (t == SpringClass::BendU.index() && !coarse.bending.is_empty())
    });
    let estimated: [bool; T] = std::array::from_fn(|t| present[t] && !held[t]);
    let mut fine = Bases::new(nf);
    let mut bases = Bases::new(n);
    let mut mags: [Vec<f64>; T] = std::array::from_fn(|_| vec![0.0; nf]);
    let mut rej = Rejections::default();
    let mut sum_k = [0.0; T];
    let mut sum_c = [0.0; T];
    let mut sums = [LsqSums::default(); T];
    let total = observations.samples.len() as u64;
    let free = &observations.free;
    for (oi, obs) in observations.samples.iter().enumerate() {
        let s = &reference.samples[obs.sample];
        fine.compute(&reference.topology, &s.cur, &obs.fine_vel);
        if reading.spring_shares() {
            spring_magnitudes(
                &reference.topology,
                &reference.material,
                &s.cur,
                &obs.fine_vel,
                &mut mags,
            );
        } else if !reading.reference_forces() {
            for t in 0..T {
                let co = reference.material.springs[t];
                for j in 0..nf {
                    let f = fine.force(t, nf, j, co);
                    mags[t][j] = dot(f, f).sqrt();
                }
            }
        }
        bases.compute(coarse, &obs.pos, &obs.vel);
        for k in 0..n {
            // A node against a body: its observed force holds the contact's.
            if !free[k] || (!reading.reference_forces() && !obs.springs_alone(k)) {
                continue;
            }
            // The type-t force the coarse node's springs must supply.
            let forces: [[f64; 3]; T] = if reading.reference_forces() {
                let mut f = [[0.0; 3]; T];
                let mut mass = 0.0;
                for &(j, w) in &weights[k] {
                    let j = j as usize;
                    mass += w * reference.masses[j];
                    for (t, ft) in f.iter_mut().enumerate() {
                        let fj = fine.force(t, nf, j, reference.material.springs[t]);
                        for c in 0..3 {
                            ft[c] += w * fj[c];
                        }
                    }
                }
                let scale = if mass > 0.0 { observations.masses[k] / mass } else { 0.0 };
                f.map(|ft| ft.map(|x| x * scale))
            } else {
                let shares = match distribution {
                    // eq. 3: the blend of the three nodes' shares.
                    Distribution::Bcd => {
                        let mut r = [0.0; T];
                        for &(j, w) in &weights[k] {
                            let j = j as usize;
                            let sum: f64 = mags.iter().map(|m| m[j]).sum();
                            if sum > 0.0 {
                                for t in 0..T {
                                    r[t] += w * mags[t][j] / sum;
                                }
                            }
                        }
                        r
                    }
                    // eqs. 4–6: kernel-weighted type forces over the total.
                    Distribution::Gkd => {
                        let mut num = [0.0; T];
                        let mut den = 0.0;
                        for &(j, w) in &weights[k] {
                            let j = j as usize;
                            for t in 0..T {
                                num[t] += w * mags[t][j];
                                den += w * mags[t][j];
                            }
                        }
                        if den > 0.0 {
                            num.map(|x| x / den)
                        } else {
                            [0.0; T]
                        }
                    }
                };
                let fs = [0, 1, 2].map(|c| obs.spring_force[c * n + k]);
                shares.map(|r| fs.map(|x| r * x))
            };
            for t in (0..T).filter(|&t| estimated[t]) {
                rej.considered[t] += 1;
                let ft = forces[t];
                let g = [0, 1, 2].map(|c| bases.elastic[t][c * n + k]);
                let h = [0, 1, 2].map(|c| bases.damping[t][c * n + k]);
                if reading.least_squares() {
                    let e = &mut sums[t];
                    e.fg += dot(ft, g);
                    e.gg += dot(g, g);
                    e.fh += dot(ft, h);
                    e.gh += dot(g, h);
                    e.hh += dot(h, h);
                    continue;
                }
                let gg = dot(g, g);
                if gg.sqrt() < 1e-4 * rest_len[t] {
                    rej.near_rest[t] += 1;
                    continue;
                }
                let kt = dot(ft, g) / gg;
                if !(kt > 0.0) {
                    rej.negative_k[t] += 1;
                    continue;
                }
                rej.accepted_k[t] += 1;
                sum_k[t] += kt;
                let hh = dot(h, h);
                if hh.sqrt() < 1e-4 {
                    rej.no_relative_velocity[t] += 1;
                    continue;
                }
                let rem = [0, 1, 2].map(|c| ft[c] - kt * g[c]);
                let ct = dot(rem, h) / hh;
                if !(ct >= 0.0) {
                    rej.negative_c[t] += 1;
                    continue;
                }
                rej.accepted_c[t] += 1;
                sum_c[t] += ct;
            }
        }
        progress(Progress {
            stage: "inverse",
            done: oi as u64 + 1,
            total,
        });
    }
    if reading.least_squares() {
        // One ratio per class: accepted as one sample each when positive.
        for t in (0..T).filter(|&t| estimated[t]) {
            let e = sums[t];
            let kt = e.fg / e.gg;
            if !(e.gg > 0.0 && kt > 0.0 && kt.is_finite()) {
                rej.negative_k[t] += 1;
                continue;
            }
            rej.accepted_k[t] = 1;
            sum_k[t] = kt;
            let ct = (e.fh - kt * e.gh) / e.hh;
            if !(e.hh > 0.0 && ct >= 0.0 && ct.is_finite()) {
                rej.negative_c[t] += 1;
                continue;
            }
            rej.accepted_c[t] = 1;
            sum_c[t] = ct;
        }
    }
    let mut material = *prior;
    let mut fallback_k = [false; T];
    let mut fallback_c = [false; T];
    for t in (0..T).filter(|&t| estimated[t]) {
        if rej.accepted_k[t] > 0 {
            material.springs[t].k = sum_k[t] / rej.accepted_k[t] as f64;
        } else {
            fallback_k[t] = true;
        }
        if rej.accepted_c[t] > 0 {
            material.springs[t].c = sum_c[t] / rej.accepted_c[t] as f64;
        } else {
            fallback_c[t] = true;
        }
    }
    InverseEstimate {
        material,
        rejections: rej,
        fallback_k,
        fallback_c,
        held,
    }
}

fn mean_rest_lengths(topology: &Topology) -> [f64; T] {
    let mut sum = [0.0; T];
    let mut count = [0usize; T];
    for g in &topology.groups {
        let t = g.class.index();
        sum[t] += g.rest.iter().sum::<f64>();
        count[t] += g.len();
    }
    std::array::from_fn(|t| if count[t] > 0 { sum[t] / count[t] as f64 } else { 1.0 })
}

/// Result of the global least-squares fit.
#[derive(Debug, Clone, PartialEq)]
pub struct LsqEstimate {
    /// The estimated coefficients.
    pub material: Material,
    /// Condition number of the column-equilibrated normal matrix.
    pub condition: f64,
    /// `|A·q − b| / |b|` at the solution.
    pub relative_residual: f64,
    /// Equations (node × component × sample) in the fit.
    pub equations: u64,
    /// Coefficients that came out non-positive and were fixed at 1e-3× the
    /// prior's, in the order of [`COEFFICIENT_NAMES`].
    pub clamped: [bool; P],
    /// Coefficients kept at the prior's by design ([`stretch_held`]), in
    /// the same order.
    pub held: [bool; P],
}

/// The global least-squares fit (see the module docs), relative to `prior`
/// (the level's `same`).
pub fn lsq_estimate(
    prior_material: &Material,
    coarse: &Topology,
    observations: &Observations,
    progress: ProgressFn<'_>,
) -> LsqEstimate {
    let n = coarse.n_nodes;
    let prior: [f64; P] = std::array::from_fn(|i| {
        let co = prior_material.springs[i % T];
        if i < T {
            co.k
        } else {
            co.c
        }
    });
    let mut ata = MatP::zeros();
    let mut atb = VecP::zeros();
    let mut btb = 0.0;
    let mut equations = 0u64;
    let mut bases = Bases::new(n);
    let total = observations.samples.len() as u64;
    for (oi, obs) in observations.samples.iter().enumerate() {
        bases.compute(coarse, &obs.pos, &obs.vel);
        for c in 0..3 {
            for k in (0..n).filter(|&k| observations.free[k] && obs.springs_alone(k)) {
                let i = c * n + k;
                let b = obs.spring_force[i];
                let row = VecP::from_fn(|j, _| {
                    let basis = if j < T {
                        &bases.elastic[j]
                    } else {
                        &bases.damping[j - T]
                    };
                    basis[i] * prior[j]
                });
                ata += row * row.transpose();
                atb += row * b;
                btb += b * b;
                equations += 1;
            }
        }
        progress(Progress {
            stage: "lsq",
            done: oi as u64 + 1,
            total,
        });
    }
    let d = VecP::from_fn(|i, _| ata[(i, i)].max(f64::MIN_POSITIVE).sqrt().recip());
    let scaled = MatP::from_fn(|i, j| ata[(i, j)] * d[i] * d[j]);
    let eig = scaled.symmetric_eigenvalues();
    let condition = eig.max() / eig.min().max(f64::MIN_POSITIVE);
    let ridge = 1e-9 * ata.trace() / P as f64;
    let held_classes = stretch_held(coarse);
    let held: [bool; P] = std::array::from_fn(|j| held_classes[j % T]);
    let mut fixed = [false; P];
    let q_min = 1e-3;
    let mut q = VecP::from_element(1.0);
    for _ in 0..P {
        // Solve for the free coefficients with the held ones at the prior
        // (q = 1) and the clamped ones at q_min.
        let mut m = ata + MatP::identity() * ridge;
        let mut rhs = atb + VecP::from_element(ridge);
        for j in 0..P {
            let value = match (held[j], fixed[j]) {
                (true, _) => 1.0,
                (false, true) => q_min,
                (false, false) => continue,
            };
            for i in 0..P {
                rhs[i] -= m[(i, j)] * value;
                m[(i, j)] = 0.0;
                m[(j, i)] = 0.0;
            }
            m[(j, j)] = 1.0;
            rhs[j] = value;
        }
        q = match m.cholesky() {
            Some(ch) => ch.solve(&rhs),
            None => m.lu().solve(&rhs).unwrap_or_else(|| VecP::from_element(1.0)),
        };
        let worst = (0..P)
            .filter(|&j| !fixed[j] && !held[j] && q[j] <= q_min)
            .min_by(|&a, &b| q[a].total_cmp(&q[b]));
        match worst {
            Some(j) => fixed[j] = true,
            None => break,
        }
    }
    let resid2 = (q.transpose() * ata * q)[0] - 2.0 * q.dot(&atb) + btb;
    let mut material = *prior_material;
    for t in 0..T {
        material.springs[t] = SpringCoeffs {
            k: q[t] * prior[t],
            c: q[t + T] * prior[t + T],
        };
    }
    LsqEstimate {
        material,
        condition,
        relative_residual: (resid2.max(0.0) / btb.max(f64::MIN_POSITIVE)).sqrt(),
        equations,
        clamped: fixed,
        held,
    }
}

/// Coefficient names in the order of the least-squares vector (K then C per
/// class, classes in [`SpringClass::index`] order).
pub const COEFFICIENT_NAMES: [&str; P] = [
    "K_st_u", "K_st_v", "K_sh", "K_b_u", "K_b_v", "C_st_u", "C_st_v", "C_sh", "C_b_u", "C_b_v",
];
