//! State transfer between resolutions: exact on rigid and affine motion,
//! momentum carried over, pins kept, time continued. (The lab's
//! `tests/switch.rs` switches mid-run and measures the jump.)

use lodcloth::lod::{transfer_state, Correlation};
use lodcloth::scene::Scene;
use lodcloth::sim::{GridShape, Orientation, State, Topology};

fn grid(nx: usize, ny: usize) -> Topology {
    Topology::grid(
        GridShape {
            nx,
            ny,
            width: 1.2,
            height: 0.8,
        },
        Orientation::Horizontal,
    )
}

/// A state whose position and velocity at every node are functions of its
/// rest position.
fn field(topo: &Topology, pos: impl Fn([f64; 3]) -> [f64; 3], vel: impl Fn([f64; 3]) -> [f64; 3]) -> State {
    let mut s = State::at_rest(topo);
    for (k, &p) in topo.rest_positions.iter().enumerate() {
        s.set_position(k, pos(p));
        s.set_velocity(k, vel(p));
    }
    s
}

fn affine(p: [f64; 3]) -> [f64; 3] {
    [
        0.3 + 1.1 * p[0] - 0.2 * p[2],
        -0.5 + 0.4 * p[0] + 0.3 * p[2],
        0.1 + 0.2 * p[0] + 0.9 * p[2],
    ]
}

fn linear_velocity(p: [f64; 3]) -> [f64; 3] {
    [1.0 - 0.5 * p[2], 2.0 * p[0], -0.3 + p[0] - p[2]]
}

#[test]
fn affine_positions_and_linear_velocities_transfer_exactly_both_ways() {
    for (a, b) in [
        ((64, 64), (40, 40)),
        ((40, 40), (64, 64)),
        ((100, 37), (50, 20)),
        ((9, 13), (17, 5)),
    ] {
        let (src, dst) = (grid(a.0, a.1), grid(b.0, b.1));
        let s = field(&src, affine, linear_velocity);
        let t = transfer_state(&src, &s, &dst).unwrap();
        let want = field(&dst, affine, linear_velocity);
        assert!(t.max_distance(&want) < 1e-12, "{a:?}→{b:?}: {}", t.max_distance(&want));
        for (v, w) in t.vel.iter().zip(&want.vel) {
            assert!((v - w).abs() < 1e-12);
        }
    }
}

fn momentum(topo: &Topology, s: &State) -> [f64; 3] {
    // Lumped masses ∝ node areas (areal density 1).
    let mut p = [0.0; 3];
    for k in 0..topo.n_nodes {
        let v = s.velocity(k);
        for c in 0..3 {
            p[c] += topo.node_areas[k] * v[c];
        }
    }
    p
}

#[test]
fn momentum_carries_over_a_level_switch() {
    let (fine, coarse) = (grid(64, 64), grid(40, 40));
    // Linear field: lumped masses have the same centre at every resolution,
    // so the momentum of a linear velocity field is preserved exactly.
    let s = field(&fine, |p| p, linear_velocity);
    let t = transfer_state(&fine, &s, &coarse).unwrap();
    let (pf, pc) = (momentum(&fine, &s), momentum(&coarse, &t));
    for c in 0..3 {
        assert!((pf[c] - pc[c]).abs() < 1e-12 * pf[c].abs().max(1.0), "{pf:?} vs {pc:?}");
    }
    // A smooth non-linear field: interpolation error is O(h²).
    let wave = |p: [f64; 3]| [(3.0 * p[0]).sin(), (2.0 * p[2]).cos(), p[0] * p[2]];
    let s = field(&fine, |p| p, wave);
    let t = transfer_state(&fine, &s, &coarse).unwrap();
    let (pf, pc) = (momentum(&fine, &s), momentum(&coarse, &t));
    let scale = pf.iter().map(|x| x.abs()).fold(0.0, f64::max);
    for c in 0..3 {
        assert!((pf[c] - pc[c]).abs() < 1e-3 * scale, "{pf:?} vs {pc:?}");
    }
}

#[test]
fn coarse_positions_equal_the_coherent_positions_of_the_metric() {
    let (fine, coarse) = (grid(33, 21), grid(12, 9));
    let s = field(&fine, |p| [p[0].sin(), p[0] * p[2], p[2].cos()], |_| [0.0; 3]);
    let t = transfer_state(&fine, &s, &coarse).unwrap();
    let corr = Correlation::between(&fine, &coarse).unwrap();
    let mut mapped = vec![0.0; 3 * coarse.n_nodes];
    corr.map(&s.pos, &mut mapped);
    assert_eq!(t.pos, mapped);
}

fn scene() -> Scene {
    let text = r#"
name = "switch"
[cloth]
width = 1.0
height = 1.0
nx = 20
ny = 20
orientation = "horizontal"
areal_density = 0.2
[springs]
structural = { k = 400.0, c = 0.04 }
shear = { k = 60.0, c = 0.006 }
bend = { k = 8.0, c = 0.0008 }
[simulation]
integrator = "symplectic_euler"
dt = 2e-4
duration = 1.0
drag = 0.2
[[pins]]
nodes = { edge = "top" }
[[forces]]
nodes = { edge = "bottom" }
total = [0.5, -1.0, 0.0]
profile = { kind = "pulse", start = 0.2, duration = 0.3 }
"#;
    Scene::from_toml(text, "switch").unwrap()
}

#[test]
fn pins_stay_pinned_after_a_transfer() {
    let s = scene();
    let mut fine = s.build().unwrap();
    for _ in 0..1500 {
        fine.step();
    }
    let mut coarse = s.build_at(11, 11).unwrap();
    let t = transfer_state(fine.topology(), fine.state(), coarse.topology()).unwrap();
    coarse.set_state(t).unwrap();
    for pin in &coarse.loads().pins {
        let k = pin.node as usize;
        assert_eq!(coarse.state().position(k), pin.at(coarse.state().time).0);
        assert_eq!(coarse.state().velocity(k), [0.0; 3]);
    }
    for _ in 0..200 {
        assert!(coarse.step().finite);
    }
}

/// Regression: the clock counted `step · dt` from t = 0, so a state handed
/// over from a run with another dt jumped in time (a switch to a level with a
/// larger dt skipped the rest of a force pulse).
#[test]
fn time_continues_from_a_transferred_state_whatever_the_dt() {
    let s = scene();
    let mut fine = s.build().unwrap();
    for _ in 0..1000 {
        fine.step();
    }
    let (t, steps) = (fine.state().time, fine.state().step);
    let mut coarse_scene = s.clone();
    coarse_scene.params.dt = 5e-4;
    let mut coarse = coarse_scene.build_at(11, 11).unwrap();
    coarse
        .set_state(transfer_state(fine.topology(), fine.state(), coarse.topology()).unwrap())
        .unwrap();
    for k in 1..=10u32 {
        coarse.step();
        assert!(
            (coarse.state().time - (t + f64::from(k) * 5e-4)).abs() < 1e-12,
            "{}",
            coarse.state().time
        );
    }
    assert_eq!(coarse.state().step, steps + 10);
}
