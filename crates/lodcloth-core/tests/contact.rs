//! Contact with rigid bodies against independent truth: Coulomb's law on an
//! incline (the sliding block's ½(g sin θ − μ g cos θ)t², to first order in
//! dt, and no motion below the angle of repose), friction dragging a cloth
//! along a moving body (v = μ g t until it rides along), no tunnelling
//! through a body thinner than one step's travel, and cloths dropped on a
//! sphere, a capsule and a box that never enter them and come to rest on top.

use std::sync::Arc;

use crate::common;

use common::{build, grid, lumped_masses, material, params};
use lodcloth::scene::Scene;
use lodcloth::sim::{
    Collider, Integrator, Loads, Orientation, PinPath, Shape, SimParams, Simulation, StabilityCheck, State, Topology,
};

const G: f64 = 9.81;

fn cloth(n: usize, size: f64) -> Arc<Topology> {
    grid(n, n, size, size, Orientation::Horizontal)
}

fn node_axis(sim: &Simulation, axis: usize) -> impl Iterator<Item = f64> + '_ {
    let n = sim.topology().n_nodes;
    sim.state().pos[axis * n..(axis + 1) * n].iter().copied()
}

fn velocity_axis(sim: &Simulation, axis: usize) -> impl Iterator<Item = f64> + '_ {
    let n = sim.topology().n_nodes;
    sim.state().vel[axis * n..(axis + 1) * n].iter().copied()
}

/// A cloth of 0.2 kg/m² with `bodies` as its only loads, from `state`.
fn on_bodies(topo: &Arc<Topology>, p: SimParams, bodies: Vec<Collider>, state: State) -> Simulation {
    let loads = Loads {
        colliders: bodies,
        ..Loads::default()
    };
    build(
        topo.clone(),
        lumped_masses(topo, 0.2),
        p,
        loads,
        state,
        StabilityCheck::Enforce,
    )
}

fn floor(gap: f64, friction: f64, path: PinPath) -> Collider {
    Collider {
        shape: Shape::Plane {
            normal: [0.0, 1.0, 0.0],
        },
        position: [0.0, -gap, 0.0],
        path,
        friction,
        clearance: gap,
    }
}

/// A 6×6 cloth lying on a floor under gravity tilted by θ (an incline in
/// the floor's frame), `steps` symplectic steps of `dt`: the mean x
/// displacement, and the largest spread between nodes (they move as one).
fn on_incline(theta: f64, mu: f64, dt: f64, steps: usize) -> (f64, f64) {
    let topo = cloth(6, 0.3);
    let mut p = params(
        dt,
        Integrator::SymplecticEuler,
        material((50.0, 0.01), (10.0, 0.002), (1.0, 0.0002)),
    );
    p.gravity = [G * theta.sin(), -G * theta.cos(), 0.0];
    let state = State::at_rest(&topo);
    let mut sim = on_bodies(&topo, p, vec![floor(0.005, mu, PinPath::Fixed)], state);
    for _ in 0..steps {
        let r = sim.step();
        assert!(r.finite);
        assert_eq!(r.contacts as usize, topo.n_nodes, "every node rests on the incline");
    }
    let moved: Vec<f64> = node_axis(&sim, 0)
        .zip(&topo.rest_positions)
        .map(|(x, r)| x - r[0])
        .collect();
    let mean = moved.iter().sum::<f64>() / moved.len() as f64;
    let spread = moved.iter().fold(0.0_f64, |m, d| m.max((d - mean).abs()));
    for y in node_axis(&sim, 1) {
        assert!(y.abs() < 1e-12, "the cloth stays on the incline's surface: y = {y:e}");
    }
    (mean, spread)
}

#[test]
fn a_cloth_on_an_incline_slides_as_coulomb_says_and_sticks_below_the_angle_of_repose() {
    let theta = 30f64.to_radians();
    let (mu, time) = (0.3, 1.0);
    let a = G * (theta.sin() - mu * theta.cos());
    let exact = 0.5 * a * time * time;
    let mut errors = Vec::new();
    for dt in [1e-3, 5e-4] {
        let steps = (time / dt).round() as usize;
        let (x, spread) = on_incline(theta, mu, dt, steps);
        assert!(spread < 1e-9, "the cloth slides as one: spread {spread:e} m");
        let error = x - exact;
        eprintln!("dt {dt:e}: slid {x:.6} m, Coulomb {exact:.6} m, error {error:.3e} m");
        assert!(error.abs() < 0.01 * exact, "slid {x} m against Coulomb's {exact} m");
        errors.push(error);
    }
    // Symplectic Euler moves the nodes with the velocity before friction
    // acts: an O(dt) error, halving with dt.
    let order = (errors[0] / errors[1]).log2();
    assert!((order - 1.0).abs() < 0.05, "error order {order:.3}, expected 1");

    // Above the angle of repose (tan 30° = 0.577 < μ = 0.7) it never moves.
    let (x, _) = on_incline(theta, 0.7, 1e-3, 1000);
    assert!(x.abs() < 1e-12, "a cloth below its angle of repose moved {x:e} m");
}

#[test]
fn a_body_moving_under_the_cloth_drags_it_by_friction_until_it_rides_along() {
    let (mu, speed, dt) = (0.3, 1.0, 1e-3);
    let topo = cloth(5, 0.2);
    let mut p = params(
        dt,
        Integrator::SymplecticEuler,
        material((50.0, 0.01), (10.0, 0.002), (1.0, 0.0002)),
    );
    p.gravity = [0.0, -G, 0.0];
    let conveyor = PinPath::Linear {
        velocity: [speed, 0.0, 0.0],
        start: 0.0,
        end: f64::INFINITY,
    };
    let state = State::at_rest(&topo);
    let mut sim = on_bodies(&topo, p, vec![floor(0.005, mu, conveyor)], state);
    for step in 1..=600 {
        sim.step();
        // Kinetic friction μ g accelerates it until it matches the belt.
        let expected = (step as f64 * mu * G * dt).min(speed);
        for v in velocity_axis(&sim, 0) {
            assert!(
                (v - expected).abs() < 1e-9,
                "step {step}: v_x {v} m/s, Coulomb on a moving body says {expected}"
            );
        }
    }
}

/// Nodes that would cross a 1 cm slab in one step (60 m/s at 1 ms: 6 cm),
/// or end a step inside it past its middle (33.8 m/s: at y = −0.1015 m,
/// nearer its bottom face), are stopped on the side they came from.
#[test]
fn a_cloth_too_fast_to_see_a_thin_slab_in_one_step_is_stopped_on_its_side() {
    for speed in [60.0, 33.834] {
        let topo = cloth(3, 0.1);
        let p = params(
            1e-3,
            Integrator::SymplecticEuler,
            material((50.0, 0.01), (10.0, 0.002), (1.0, 0.0002)),
        );
        let (gap, centre, half) = (0.002, -0.1, 0.005);
        let slab = Collider {
            shape: Shape::Cuboid {
                half_extents: [1.0, half, 1.0],
            },
            position: [0.05, centre, 0.05],
            path: PinPath::Fixed,
            friction: 0.0,
            clearance: gap,
        };
        let mut state = State::at_rest(&topo);
        let n = topo.n_nodes;
        state.vel[n..2 * n].fill(-speed);
        let mut sim = on_bodies(&topo, p, vec![slab], state);
        let top = centre + half + gap;
        for _ in 0..20 {
            sim.step();
            for y in node_axis(&sim, 1) {
                assert!(
                    y >= top - 1e-9,
                    "{speed} m/s: a node passed the slab: y = {y} m, its top is at {top} m"
                );
            }
        }
        for v in velocity_axis(&sim, 1) {
            assert!(
                v.abs() < 1e-9,
                "{speed} m/s: the slab did not stop the cloth: v_y = {v} m/s"
            );
        }
    }
}

/// A cloth dropped on each body never comes closer than the clearance and
/// settles with its middle on the body's top.
#[test]
fn a_cloth_dropped_on_a_sphere_a_capsule_a_box_or_a_cylinder_never_enters_it_and_rests_on_top() {
    let size = 1.0;
    let gap = 0.004;
    let mid = [0.5 * size, -0.3, 0.5 * size];
    let bodies = [
        ("sphere", Shape::Sphere { radius: 0.2 }, 0.2),
        (
            "capsule",
            Shape::Capsule {
                half_axis: [0.0, 0.0, 0.25],
                radius: 0.15,
            },
            0.15,
        ),
        (
            "box",
            Shape::Cuboid {
                half_extents: [0.25, 0.1, 0.25],
            },
            0.1,
        ),
        (
            "cylinder",
            Shape::Cylinder {
                radius: 0.25,
                half_height: 0.1,
            },
            0.1,
        ),
    ];
    for (name, shape, height) in bodies {
        let topo = cloth(17, size);
        let mut p = params(
            1e-3,
            Integrator::SymplecticEuler,
            material((200.0, 0.02), (40.0, 0.004), (2.0, 0.0004)),
        );
        p.gravity = [0.0, -G, 0.0];
        p.drag = 2.0;
        let body = Collider {
            shape,
            position: mid,
            path: PinPath::Fixed,
            friction: 0.5,
            clearance: gap,
        };
        let state = State::at_rest(&topo);
        let mut sim = on_bodies(&topo, p, vec![body], state);
        let mut touched = 0;
        for _ in 0..3000 {
            let r = sim.step();
            assert!(r.finite, "{name}: diverged");
            touched = touched.max(r.contacts);
            let n = topo.n_nodes;
            for k in 0..n {
                let x = [0, 1, 2].map(|c| sim.state().pos[c * n + k]);
                let d = body.distance(x, r.time);
                assert!(
                    d >= gap - 1e-9,
                    "{name}: node {k} at {d:e} m from the surface at t = {}",
                    r.time
                );
            }
        }
        let centre = topo.n_nodes / 2;
        let y = sim.state().position(centre)[1];
        let rest_top = mid[1] + height + gap;
        eprintln!("{name}: up to {touched} nodes in contact; middle at y = {y:.5} m, top + gap {rest_top:.5} m");
        assert!(touched > 0, "{name}: the cloth never reached the body");
        assert!(
            (y - rest_top).abs() < 1e-3,
            "{name}: middle at {y} m, the body's top at {rest_top} m"
        );
    }
}

#[test]
fn a_collider_missing_a_field_or_given_another_shapes_field_is_refused_naming_it() {
    let scene = |body: &str| {
        format!(
            "name = \"t\"\n[cloth]\nwidth = 1.0\nheight = 1.0\nnx = 4\nny = 4\nareal_density = 0.2\n\
             [springs]\nstructural = {{ k = 100.0, c = 0.1 }}\nshear = {{ k = 10.0, c = 0.01 }}\n\
             bend = {{ k = 1.0, c = 0.001 }}\n[simulation]\nintegrator = \"symplectic_euler\"\n\
             dt = 1e-3\nduration = 1.0\n[[colliders]]\n{body}\n"
        )
    };
    let refused = |body: &str| match Scene::from_toml(&scene(body), "t.toml") {
        Ok(_) => panic!("accepted: {body}"),
        Err(e) => e.to_string(),
    };
    let e = refused("shape = \"sphere\"\ncenter = [0.5, -1.0, 0.5]");
    assert!(e.contains("colliders[0].radius: a sphere needs it"), "{e}");
    let e = refused("shape = \"box\"\ncenter = [0.5, -1.0, 0.5]\nsize = [1.0, 0.0, 1.0]\nradius = 0.2");
    assert!(e.contains("colliders[0].radius: a box has no radius"), "{e}");
    assert!(e.contains("colliders[0].size[1]: must be positive"), "{e}");
    let e = refused("shape = \"plane\"\npoint = [0.0, -1.0, 0.0]\nnormal = [0.0, 0.0, 0.0]\nfriction = -1.0");
    assert!(e.contains("colliders[0].normal: must not be zero"), "{e}");
    assert!(e.contains("colliders[0].friction: must be finite and ≥ 0"), "{e}");
    let e = refused("shape = \"cone\"");
    assert!(e.contains("cone"), "{e}");

    // A body the rest cloth starts inside, at the level built.
    let inside = Scene::from_toml(
        &scene("shape = \"sphere\"\ncenter = [0.5, 0.0, 0.5]\nradius = 0.2"),
        "t.toml",
    )
    .expect("a valid scene");
    let e = match inside.build_at(8, 8) {
        Ok(_) => panic!("a cloth starting inside a sphere was built"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("colliders[0]: ") && e.contains("start inside it") && e.contains("8×8"),
        "{e}"
    );
}

/// What clients draw of a body lies on its surface and faces outwards.
#[test]
fn the_drawing_of_each_body_lies_on_its_surface_and_faces_out() {
    let shapes = [
        Shape::Plane {
            normal: [0.6, 0.0, 0.8],
        },
        Shape::Sphere { radius: 0.3 },
        Shape::Capsule {
            half_axis: [0.1, 0.2, -0.2],
            radius: 0.15,
        },
        Shape::Cuboid {
            half_extents: [0.5, 0.1, 0.25],
        },
        Shape::Cylinder {
            radius: 0.09,
            half_height: 0.01,
        },
    ];
    for shape in shapes {
        let t = shape.triangles(4.0);
        assert!(t.len() >= 6 && t.len() % 3 == 0, "{shape:?}: {} vertices", t.len());
        let mut faced = 0;
        for tri in t.chunks(3) {
            for v in tri {
                let (d, _) = shape.distance(*v);
                assert!(d.abs() < 1e-9, "{shape:?}: vertex {v:?} is {d:e} m off the surface");
            }
            let (a, b, c) = (tri[0], tri[1], tri[2]);
            let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = common::cross(e1, e2);
            if common::norm(n) < 1e-12 {
                continue; // a pole's degenerate triangle
            }
            let mid = [0, 1, 2].map(|i| (a[i] + b[i] + c[i]) / 3.0);
            let (_, outward) = shape.distance(mid);
            assert!(
                n[0] * outward[0] + n[1] * outward[1] + n[2] * outward[2] > 0.0,
                "{shape:?}: a triangle at {mid:?} faces inwards"
            );
            faced += 1;
        }
        assert!(faced * 3 >= t.len() / 2, "{shape:?}: too few proper triangles");
    }
}

/// A state made elsewhere (another level's, mapped onto this one) with a
/// node inside a body is put right when it is set, before any step.
#[test]
fn a_state_set_with_a_node_inside_a_body_has_it_put_on_the_surface() {
    let topo = cloth(5, 0.4);
    let p = params(
        1e-3,
        Integrator::SymplecticEuler,
        material((50.0, 0.01), (10.0, 0.002), (1.0, 0.0002)),
    );
    let ball = Collider {
        shape: Shape::Sphere { radius: 0.1 },
        position: [0.2, -0.2, 0.2],
        path: PinPath::Fixed,
        friction: 0.0,
        clearance: 0.003,
    };
    let mut sim = on_bodies(&topo, p, vec![ball], State::at_rest(&topo));
    let mut state = State::at_rest(&topo);
    let (k, n) = (12, topo.n_nodes); // the middle node
    state.pos[n + k] = -0.15; // 5 cm inside the ball, above its centre
    state.vel[n + k] = -1.0; // and moving further in
    sim.set_state(state).expect("fits");
    let x = sim.state().position(k);
    let d = ball.distance(x, 0.0);
    assert!(
        (d - ball.clearance).abs() < 1e-12,
        "node {k} is {d} m from the ball after set_state"
    );
    assert!(
        sim.state().vel[n + k].abs() < 1e-12,
        "still moving into the ball: {}",
        sim.state().vel[n + k]
    );
}
