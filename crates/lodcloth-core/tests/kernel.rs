//! The vectorised force kernel equals a straightforward scalar evaluation of
//! the model, written here from the equations: springs (Sung 2018 eq. 1, with
//! the Bayraktar stiffness adjustment), node loads, tethers, wind, gravity and drag,
//! on random states; and the gather path (arbitrary node pairs) equals the
//! grid path (stencil runs) on the same springs.

use crate::common;

use std::sync::Arc;

use common::{as_gather_topology, build, grid, lumped_masses, material, params, Rng};
use lodcloth::sim::{
    Integrator, Loads, NodeLoad, Orientation, PinPath, Profile, SimParams, Simulation, SpringKernel, SpringKind,
    StabilityCheck, State, StiffnessAdjustment, Tether, Topology, Wind,
};

/// Random state: rest shape moved by up to ±30% of the spacing, velocities
/// up to ±1 m/s, at t = 0.37 s.
fn random_state(topology: &Topology, rng: &mut Rng, h: f64) -> State {
    let mut s = common::perturbed_state(topology, rng, 0.3 * h, 1.0);
    s.time = 0.37;
    s
}

fn test_params(adjust: Option<f64>) -> SimParams {
    let mut p = params(
        1e-5,
        Integrator::SymplecticEuler,
        material((40.0, 0.3), (9.0, 0.07), (2.5, 0.02)),
    );
    p.gravity = [0.4, -9.81, 1.3];
    p.drag = 0.7;
    p.stiffness_adjustment = adjust.map(|allowed| StiffnessAdjustment { allowed });
    p
}

/// Loads on a few nodes (one time-varying) and two pins, one of them moving.
fn test_loads(topology: &Topology, with_wind: bool) -> Loads {
    let n = topology.n_nodes as u32;
    Loads {
        forces: vec![
            NodeLoad {
                nodes: vec![n - 1, n / 2],
                shares: vec![0.25, 0.75],
                force: [0.3, -0.2, 0.5],
                profile: Profile::Constant,
            },
            NodeLoad {
                nodes: vec![1, n - 2],
                shares: vec![0.5, 0.5],
                force: [-0.1, 0.4, 0.2],
                profile: Profile::Sine {
                    frequency: 1.7,
                    phase: 0.3,
                    amplitude: 0.8,
                    offset: 0.1,
                },
            },
        ],
        wind: with_wind.then_some(Wind {
            velocity: [2.0, -1.0, 3.5],
            profile: Profile::Ramp { start: 0.0, end: 1.0 },
            air_density: 1.2,
            drag_coefficient: 1.1,
        }),
        pins: vec![
            lodcloth::sim::Pin {
                node: 0,
                anchor: topology.rest_positions[0],
                path: PinPath::Fixed,
            },
            lodcloth::sim::Pin {
                node: n - 3,
                anchor: topology.rest_positions[(n - 3) as usize],
                path: PinPath::Sine {
                    amplitude: [0.01, 0.02, 0.0],
                    frequency: 2.0,
                },
            },
        ],
        tethers: vec![
            Tether {
                node: n / 3,
                target: [0.2, -0.1, 0.4],
                stiffness: 3.0,
                damping: 0.2,
                profile: Profile::Constant,
            },
            Tether {
                node: 2,
                target: [-0.1, 0.3, 0.0],
                stiffness: 1.5,
                damping: 0.0,
                profile: Profile::Ramp { start: 0.0, end: 1.0 },
            },
        ],
        colliders: Vec::new(),
    }
}

/// Area-weighted unit normals: Σ over a node's triangles of (b − a) × (c − a), normalised.
fn scalar_normals(topology: &Topology, state: &State) -> Vec<[f64; 3]> {
    let mut nrm = vec![[0.0; 3]; topology.n_nodes];
    for t in &topology.triangles {
        let [a, b, c] = t.map(|k| state.position(k as usize));
        let cr = common::cross(
            [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
            [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
        );
        for &k in t {
            for d in 0..3 {
                nrm[k as usize][d] += cr[d];
            }
        }
    }
    nrm.iter()
        .map(|v| {
            let l = common::norm(*v);
            if l > 0.0 {
                v.map(|x| x / l)
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// Accelerations evaluated directly from the model's equations.
fn scalar_accelerations(sim: &Simulation) -> Vec<[f64; 3]> {
    let (topo, p, loads, state) = (sim.topology(), sim.params(), sim.loads(), sim.state());
    let adjust = p.stiffness_adjustment.map_or(f64::INFINITY, |a| 1.0 + a.allowed);
    let mut f = common::scalar_spring_forces(topo, &p.material, adjust, state);
    let t = state.time;
    for load in &loads.forces {
        let s = load.profile.at(t);
        for (&k, &share) in load.nodes.iter().zip(&load.shares) {
            for c in 0..3 {
                f[k as usize][c] += share * s * load.force[c];
            }
        }
    }
    for tether in &loads.tethers {
        // F = s(t) · (k (target − x) − c v).
        let (k, s) = (tether.node as usize, tether.profile.at(t));
        let (x, v) = (state.position(k), state.velocity(k));
        for c in 0..3 {
            f[k][c] += s * (tether.stiffness * (tether.target[c] - x[c]) - tether.damping * v[c]);
        }
    }
    if let Some(w) = &loads.wind {
        // F = ½ ρ C_d A |w_n| w_n n̂ with w_n = (s·w − v)·n̂.
        let normals = scalar_normals(topo, state);
        let s = w.profile.at(t);
        for k in 0..topo.n_nodes {
            let v = state.velocity(k);
            let n = normals[k];
            let wn: f64 = (0..3).map(|c| (s * w.velocity[c] - v[c]) * n[c]).sum();
            let mag = 0.5 * w.air_density * w.drag_coefficient * topo.node_areas[k] * wn.abs() * wn;
            for c in 0..3 {
                f[k][c] += mag * n[c];
            }
        }
    }
    let pinned: Vec<bool> = (0..topo.n_nodes)
        .map(|k| loads.pins.iter().any(|pin| pin.node as usize == k))
        .collect();
    (0..topo.n_nodes)
        .map(|k| {
            if pinned[k] {
                return [0.0; 3];
            }
            let v = state.velocity(k);
            [0, 1, 2].map(|c| f[k][c] / sim.masses()[k] + p.gravity[c] - p.drag * v[c])
        })
        .collect()
}

/// Largest |a_lib − a_scalar| relative to the largest |a_scalar|.
fn kernel_error(sim: &mut Simulation) -> f64 {
    let expected = scalar_accelerations(sim);
    let n = sim.topology().n_nodes;
    let got = sim.accelerations().to_vec();
    let scale = expected.iter().map(|a| common::norm(*a)).fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    for (k, e) in expected.iter().enumerate() {
        for c in 0..3 {
            worst = worst.max((got[c * n + k] - e[c]).abs());
        }
    }
    worst / scale
}

fn sim_on(topology: Arc<Topology>, state: State, adjust: Option<f64>, wind: bool) -> Simulation {
    let masses = lumped_masses(&topology, 0.2);
    let loads = test_loads(&topology, wind);
    build(
        topology,
        masses,
        test_params(adjust),
        loads,
        state,
        StabilityCheck::Force,
    )
}

const SIZES: [(usize, usize); 7] = [(2, 2), (3, 3), (5, 4), (8, 8), (9, 4), (17, 6), (4, 19)];

#[test]
fn vectorised_kernel_equals_scalar_sung_eq1_plus_loads_gravity_and_drag_on_random_states() {
    let mut rng = Rng::new(42);
    let mut largest: f64 = 0.0;
    for (nx, ny) in SIZES {
        for orientation in [Orientation::Horizontal, Orientation::Vertical] {
            let topo = grid(nx, ny, 0.4, 0.3, orientation);
            let h = 0.3 / (ny - 1) as f64;
            let state = random_state(&topo, &mut rng, h);
            let err = kernel_error(&mut sim_on(topo, state, None, false));
            assert!(err < 1e-12, "{nx}x{ny} {orientation:?}: relative error {err:e}");
            largest = largest.max(err);
        }
    }
    eprintln!("kernel vs scalar eq. 1 + loads + gravity + drag: largest relative difference {largest:.1e}");
}

#[test]
fn kernel_with_stiffness_adjustment_equals_scalar_k_times_l_over_l0_beyond_the_allowed_strain() {
    let mut rng = Rng::new(5);
    for (nx, ny) in SIZES {
        let topo = grid(nx, ny, 0.4, 0.3, Orientation::Horizontal);
        let state = random_state(&topo, &mut rng, 0.3 / (ny - 1) as f64);
        // 5% allowed: about half of the randomly stretched springs are beyond it.
        let err = kernel_error(&mut sim_on(topo, state, Some(0.05), false));
        assert!(err < 1e-12, "{nx}x{ny}: relative error {err:e}");
    }
}

#[test]
fn wind_force_equals_half_rho_cd_area_times_normal_relative_speed_squared() {
    let mut rng = Rng::new(9);
    for (nx, ny) in [(3, 3), (9, 4), (17, 6)] {
        let topo = grid(nx, ny, 0.4, 0.3, Orientation::Vertical);
        let state = random_state(&topo, &mut rng, 0.3 / (ny - 1) as f64);
        let err = kernel_error(&mut sim_on(topo, state, None, true));
        assert!(err < 1e-12, "{nx}x{ny}: relative error {err:e}");
    }
}

/// The f32 kernel (issue 21's live path) is the scalar f64 model to f32
/// rounding: on a state both can hold exactly (rounded to f32 first), every
/// force within 2e-6 of the largest force, energy within 1e-5 and strains
/// within 1e-6, on grids and on gathered pairs, with and without the
/// stiffness adjustment. Measured: 8e-7, 4e-7 and 3e-7 at worst.
#[test]
fn the_f32_kernel_equals_scalar_sung_eq1_to_f32_rounding() {
    let mut rng = Rng::new(23);
    let (mut worst_force, mut worst_energy, mut worst_strain) = (0.0f64, 0.0f64, 0.0f64);
    for (nx, ny) in SIZES.into_iter().chain([(64, 64), (63, 17)]) {
        let grid_topology = grid(nx, ny, 0.4, 0.3, Orientation::Horizontal);
        let mut state = random_state(&grid_topology, &mut rng, 0.3 / (ny - 1) as f64);
        for x in state.pos.iter_mut().chain(state.vel.iter_mut()) {
            *x = f64::from(*x as f32);
        }
        let pos: Vec<f32> = state.pos.iter().map(|&x| x as f32).collect();
        let vel: Vec<f32> = state.vel.iter().map(|&x| x as f32).collect();
        let material = test_params(None).material;
        for topology in [grid_topology.clone(), Arc::new(as_gather_topology(&grid_topology))] {
            let mut kernel = SpringKernel::<f32>::new(topology.clone());
            for adjust in [None, Some(0.05)] {
                let ratio = adjust.map_or(f64::INFINITY, |a| 1.0 + a);
                let expected = common::scalar_spring_forces(&topology, &material, ratio, &state);
                let mut force = vec![0.0f32; pos.len()];
                let totals = kernel.add_forces(&material, adjust, &pos, &vel, &mut force);
                let n = topology.n_nodes;
                let scale = expected.iter().map(|f| common::norm(*f)).fold(0.0, f64::max);
                for (k, e) in expected.iter().enumerate() {
                    for c in 0..3 {
                        worst_force = worst_force.max((f64::from(force[c * n + k]) - e[c]).abs() / scale);
                    }
                }
                let energy = common::scalar_elastic_energy(&topology, &material, &state);
                worst_energy = worst_energy.max((totals.elastic_energy - energy).abs() / energy);
                for kind in SpringKind::ALL {
                    let mut kinds = [false; 3];
                    kinds[kind.index()] = true;
                    let strain = common::scalar_max_strain(&topology, &state, kinds);
                    if strain == f64::NEG_INFINITY {
                        continue; // no spring of this kind (a 2×2 grid has no bend springs)
                    }
                    worst_strain = worst_strain.max((totals.max_strain[kind.index()] - strain).abs());
                }
            }
        }
    }
    eprintln!("f32 kernel against scalar f64: force {worst_force:.1e} of the largest, energy {worst_energy:.1e}, strain {worst_strain:.1e}");
    assert!(worst_force < 2e-6, "forces off by {worst_force:e} of the largest");
    assert!(worst_energy < 1e-5, "energy off by {worst_energy:e}");
    assert!(worst_strain < 1e-6, "strain off by {worst_strain:e}");
}

#[test]
fn gather_path_equals_grid_path_on_the_same_springs() {
    let mut rng = Rng::new(17);
    for (nx, ny) in SIZES {
        let topo = grid(nx, ny, 0.4, 0.3, Orientation::Horizontal);
        let state = random_state(&topo, &mut rng, 0.3 / (ny - 1) as f64);
        let gather = Arc::new(as_gather_topology(&topo));
        assert!(gather.groups.iter().all(|g| g.stencil_offset.is_none()));
        let mut a = sim_on(topo, state.clone(), Some(0.05), false);
        let mut b = sim_on(gather, state, Some(0.05), false);
        let (aa, ab) = (a.accelerations().to_vec(), b.accelerations().to_vec());
        let scale = aa.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let worst = aa.iter().zip(&ab).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(
            worst <= 1e-12 * scale,
            "{nx}x{ny}: grid vs gather differ by {worst:e} (scale {scale:e})"
        );
        assert!(kernel_error(&mut b) < 1e-12);
        // The same by-products: one step later, equal energies and strains.
        let (ra, rb) = (a.step(), b.step());
        assert!((ra.elastic_energy - rb.elastic_energy).abs() <= 1e-12 * ra.elastic_energy);
        for kind in SpringKind::ALL {
            assert!((ra.max_strain[kind.index()] - rb.max_strain[kind.index()]).abs() < 1e-12);
        }
    }
}

#[test]
fn gather_path_on_a_hand_built_point_cloud_equals_scalar_evaluation() {
    // A tetrahedron plus a tail: no grid at all, three groups of different kinds.
    let rest = vec![
        [0.0, 0.0, 0.0],
        [0.1, 0.0, 0.0],
        [0.0, 0.12, 0.0],
        [0.03, 0.04, 0.09],
        [0.2, 0.1, 0.05],
    ];
    let mut topo = common::pairs_topology(rest.clone(), &[(0, 1), (0, 2), (1, 2)], SpringKind::Structural);
    let shear = common::pairs_topology(rest.clone(), &[(0, 3), (1, 3), (2, 3)], SpringKind::Shear);
    let bend = common::pairs_topology(rest, &[(4, 1), (3, 4)], SpringKind::Bend);
    topo.groups.extend(shear.groups.into_iter().chain(bend.groups));
    topo.node_areas = vec![0.01; 5];
    let topo = Arc::new(topo);
    let mut rng = Rng::new(23);
    for _ in 0..20 {
        let state = random_state(&topo, &mut rng, 0.1);
        let p = test_params(Some(0.05));
        let loads = Loads {
            pins: common::fixed_pins(&topo, &[2]),
            ..Loads::default()
        };
        let mut sim = build(
            topo.clone(),
            vec![0.01, 0.02, 0.015, 0.03, 0.01],
            p,
            loads,
            state,
            StabilityCheck::Force,
        );
        let err = kernel_error(&mut sim);
        assert!(err < 1e-12, "relative error {err:e}");
    }
}

#[test]
fn reported_strains_are_the_largest_l_over_l0_minus_one_per_kind() {
    let mut rng = Rng::new(31);
    let topo = grid(9, 7, 0.4, 0.3, Orientation::Horizontal);
    let state = random_state(&topo, &mut rng, 0.05);
    let mut sim = sim_on(topo, state, None, false);
    let r = sim.step();
    for kind in SpringKind::ALL {
        let mut kinds = [false; 3];
        kinds[kind.index()] = true;
        let expected = common::scalar_max_strain(sim.topology(), sim.state(), kinds);
        assert!(
            (r.max_strain[kind.index()] - expected).abs() < 1e-12,
            "{kind}: {} vs {expected}",
            r.max_strain[kind.index()]
        );
    }
}
