//! Helpers shared by the integration tests: small hand-built cloths, a
//! deterministic random generator, and an independent scalar evaluation of
//! the spring model (Sung 2018 eq. 1) that the tests compare the library with.
//!
//! Every test binary includes this module but uses only part of it.
#![allow(dead_code)]

use std::sync::Arc;

use lodcloth::sim::{
    CgSettings, GridShape, Integrator, Loads, Material, Orientation, Pin, PinPath, SimParams, Simulation, SpringClass,
    SpringCoeffs, SpringGroup, SpringKind, StabilityCheck, State, StepReport, Topology,
};

/// SplitMix64: a tiny deterministic generator, so no test depends on a seed
/// from the environment.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        let u = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }

    /// Uniform in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }

    /// True once in `one_in` draws on average.
    pub fn chance(&mut self, one_in: usize) -> bool {
        self.below(one_in) == 0
    }

    /// `base + below(spread)` random bytes.
    pub fn bytes(&mut self, base: usize, spread: usize) -> Vec<u8> {
        let len = base + self.below(spread);
        (0..len).map(|_| self.next_u64() as u8).collect()
    }
}

/// The same coefficients for every spring kind.
pub fn uniform_material(k: f64, c: f64) -> Material {
    Material::isotropic([SpringCoeffs { k, c }; 3])
}

/// Per-kind coefficients: (structural, shear, bend) as (k, c) pairs.
pub fn material(st: (f64, f64), sh: (f64, f64), be: (f64, f64)) -> Material {
    Material::isotropic([
        SpringCoeffs { k: st.0, c: st.1 },
        SpringCoeffs { k: sh.0, c: sh.1 },
        SpringCoeffs { k: be.0, c: be.1 },
    ])
}

/// Parameters with no gravity, no drag and no strain control.
pub fn params(dt: f64, integrator: Integrator, material: Material) -> SimParams {
    SimParams {
        dt,
        integrator,
        material,
        gravity: [0.0; 3],
        drag: 0.0,
        stiffness_adjustment: None,
        strain_limit: None,
        cg: CgSettings::default(),
        self_contact: None,
    }
}

/// An `nx × ny` grid of `width × height` metres.
pub fn grid(nx: usize, ny: usize, width: f64, height: f64, orientation: Orientation) -> Arc<Topology> {
    Arc::new(Topology::grid(GridShape { nx, ny, width, height }, orientation))
}

/// Node masses `areal_density × node area` (the lumped convention).
pub fn lumped_masses(topology: &Topology, areal_density: f64) -> Vec<f64> {
    topology.node_areas.iter().map(|a| a * areal_density).collect()
}

/// Fixed pins on `nodes` at their rest positions.
pub fn fixed_pins(topology: &Topology, nodes: &[usize]) -> Vec<Pin> {
    nodes
        .iter()
        .map(|&k| Pin {
            node: k as u32,
            anchor: topology.rest_positions[k],
            path: PinPath::Fixed,
        })
        .collect()
}

/// A topology of point masses joined by springs of one kind, given as node
/// pairs; rest lengths are the distances in `rest_positions`. No grid, no
/// triangles: the force kernel takes its gather path.
pub fn pairs_topology(rest_positions: Vec<[f64; 3]>, pairs: &[(u32, u32)], kind: SpringKind) -> Topology {
    let rest = pairs
        .iter()
        .map(|&(a, b)| dist(rest_positions[a as usize], rest_positions[b as usize]))
        .collect();
    let n = rest_positions.len();
    Topology {
        n_nodes: n,
        rest_positions,
        node_areas: vec![0.0; n],
        groups: vec![SpringGroup::from_pairs(SpringClass::along_u(kind), pairs, rest)],
        triangles: Vec::new(),
        grid: None,
        mesh: None,
        bending: Default::default(),
    }
}

/// The same springs as `topology`, re-expressed as plain node-pair groups
/// (one per original group, same order): no stencils, no grid.
pub fn as_gather_topology(topology: &Topology) -> Topology {
    let groups = topology
        .groups
        .iter()
        .map(|g| {
            let pairs: Vec<(u32, u32)> = g.a.iter().zip(&g.b).map(|(&a, &b)| (a, b)).collect();
            SpringGroup::from_pairs(g.class, &pairs, g.rest.clone())
        })
        .collect();
    Topology {
        n_nodes: topology.n_nodes,
        rest_positions: topology.rest_positions.clone(),
        node_areas: topology.node_areas.clone(),
        groups,
        triangles: topology.triangles.clone(),
        grid: None,
        mesh: None,
        bending: Default::default(),
    }
}

/// Build a simulation, panicking with the error on failure.
pub fn build(
    topology: Arc<Topology>,
    masses: Vec<f64>,
    params: SimParams,
    loads: Loads,
    state: State,
    check: StabilityCheck,
) -> Simulation {
    match Simulation::new(topology, masses, params, loads, state, check) {
        Ok(sim) => sim,
        Err(e) => panic!("simulation refused: {e}"),
    }
}

/// Rest state with every position moved by up to ±`dx` and every velocity
/// set uniformly in ±`dv` (per component).
pub fn perturbed_state(topology: &Topology, rng: &mut Rng, dx: f64, dv: f64) -> State {
    let mut s = State::at_rest(topology);
    for x in s.pos.iter_mut() {
        *x += rng.uniform(-dx, dx);
    }
    for v in s.vel.iter_mut() {
        *v = rng.uniform(-dv, dv);
    }
    s
}

/// Take `steps` steps; panics if the simulation diverges. Returns the last report.
pub fn run(sim: &mut Simulation, steps: usize) -> StepReport {
    let mut last = None;
    for _ in 0..steps {
        let r = sim.step();
        assert!(r.finite, "diverged at step {}", r.step);
        last = Some(r);
    }
    last.expect("at least one step")
}

pub fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt()
}

pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// Σ m v over all nodes.
pub fn momentum(state: &State, masses: &[f64]) -> [f64; 3] {
    let mut p = [0.0; 3];
    for (k, &m) in masses.iter().enumerate() {
        let v = state.velocity(k);
        for c in 0..3 {
            p[c] += m * v[c];
        }
    }
    p
}

/// Σ m x × v about the origin.
pub fn angular_momentum(state: &State, masses: &[f64]) -> [f64; 3] {
    let mut l = [0.0; 3];
    for (k, &m) in masses.iter().enumerate() {
        let h = cross(state.position(k), state.velocity(k));
        for c in 0..3 {
            l[c] += m * h[c];
        }
    }
    l
}

/// Largest node-wise distance between two position sets.
pub fn max_distance(a: &State, b: &State) -> f64 {
    a.max_distance(b)
}

/// Spring forces by direct scalar evaluation of Sung 2018 eq. 1, written
/// independently of the library's vectorised kernel: for a spring a–b with
/// d = x_b − x_a, L = |d|, u = d / L, the force on a is
/// `K_eff (L − L0) u + C ((v_b − v_a)·u) u` and the force on b its opposite.
/// `K_eff` is `K · L / L0` when L / L0 exceeds `adjust_ratio` (Bayraktar
/// stiffness adjustment, Yu eq. 6), else `K`. Returns per-node forces.
pub fn scalar_spring_forces(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    state: &State,
) -> Vec<[f64; 3]> {
    let mut f = vec![[0.0; 3]; topology.n_nodes];
    for g in &topology.groups {
        let co = material.get(g.class);
        for s in 0..g.len() {
            let (a, b) = (g.a[s] as usize, g.b[s] as usize);
            let (xa, xb) = (state.position(a), state.position(b));
            let (va, vb) = (state.velocity(a), state.velocity(b));
            let d = [xb[0] - xa[0], xb[1] - xa[1], xb[2] - xa[2]];
            let l = norm(d);
            let u = [d[0] / l, d[1] / l, d[2] / l];
            let l0 = g.rest[s];
            let k = if l / l0 > adjust_ratio { co.k * l / l0 } else { co.k };
            let vrel = (vb[0] - va[0]) * u[0] + (vb[1] - va[1]) * u[1] + (vb[2] - va[2]) * u[2];
            let mag = k * (l - l0) + co.c * vrel;
            for c in 0..3 {
                f[a][c] += mag * u[c];
                f[b][c] -= mag * u[c];
            }
        }
    }
    f
}

/// Σ ½ K (L − L0)² over all springs, evaluated directly.
pub fn scalar_elastic_energy(topology: &Topology, material: &Material, state: &State) -> f64 {
    let mut e = 0.0;
    for g in &topology.groups {
        let k = material.get(g.class).k;
        for s in 0..g.len() {
            let l = dist(state.position(g.a[s] as usize), state.position(g.b[s] as usize));
            e += 0.5 * k * (l - g.rest[s]).powi(2);
        }
    }
    e
}

/// Largest strain L / L0 − 1 over the springs of the given kinds, evaluated directly.
pub fn scalar_max_strain(topology: &Topology, state: &State, kinds: [bool; 3]) -> f64 {
    let mut worst = f64::NEG_INFINITY;
    for g in topology.groups.iter().filter(|g| kinds[g.kind().index()]) {
        for s in 0..g.len() {
            let l = dist(state.position(g.a[s] as usize), state.position(g.b[s] as usize));
            worst = worst.max(l / g.rest[s] - 1.0);
        }
    }
    worst
}

/// Total energy (kinetic + elastic + gravity) of a state, evaluated directly
/// (kinetic over free nodes, `free[k]` false for pins).
pub fn scalar_total_energy(
    topology: &Topology,
    material: &Material,
    masses: &[f64],
    free: &[bool],
    gravity: [f64; 3],
    state: &State,
) -> f64 {
    let mut e = scalar_elastic_energy(topology, material, state);
    for k in 0..topology.n_nodes {
        if free[k] {
            let (x, v) = (state.position(k), state.velocity(k));
            e += 0.5 * masses[k] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
            e -= masses[k] * (gravity[0] * x[0] + gravity[1] * x[1] + gravity[2] * x[2]);
        }
    }
    e
}

/// `scene`'s whole run recorded as a reference at the paper's strides.
pub fn record_whole_run(scene: &lodcloth::scene::Scene) -> Arc<lodcloth::estimate::Reference> {
    let spec = lodcloth::estimate::RecordSpec {
        frames: scene.steps(),
        ..lodcloth::estimate::RecordSpec::PAPER
    };
    let sim = scene.build().expect("builds");
    Arc::new(lodcloth::estimate::Reference::record(sim, spec, &mut |_, _| {}).expect("records"))
}
