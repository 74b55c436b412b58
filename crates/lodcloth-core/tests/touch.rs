//! Live input (`touch`): an input given in material coordinates acts on the
//! same material point with the same total at every level, obeys the
//! mechanics it claims (momentum, static equilibrium, linear pin moves),
//! keeps a level stable or is refused, and survives a level switch.

use lodcloth::mesh::RestSurface;
use lodcloth::scene::Scene;
use lodcloth::sim::{Simulation, StabilityCheck};
use lodcloth::touch::{Input, Patch, Touch, TouchError};

/// A free cloth in zero gravity (nothing pinned), with drag so it settles.
const FREE: &str = r#"
name = "free"

[cloth]
width = 1.2
height = 0.8
nx = 24
ny = 16
orientation = "horizontal"
areal_density = 0.2

[springs]
structural = { k = 400.0, c = 0.04 }
shear = { k = 60.0, c = 0.006 }
bend = { k = 8.0, c = 0.0008 }

[simulation]
integrator = "symplectic_euler"
dt = 1e-4
duration = 10.0
gravity = [0.0, 0.0, 0.0]
drag = 2.0
"#;

fn free() -> Scene {
    Scene::from_toml(FREE, "<free>").expect("the free scene is valid")
}

/// `scene` at `nx × ny` and its own dt (every level here is coarser, so
/// stable at it).
fn at(scene: &Scene, nx: usize, ny: usize) -> Simulation {
    scene.build_at(nx, ny).expect("builds")
}

const LEVELS: [(usize, usize); 3] = [(24, 16), (13, 9), (7, 5)];

fn momentum(sim: &Simulation) -> [f64; 3] {
    let n = sim.topology().n_nodes;
    let v = &sim.state().vel;
    [0, 1, 2].map(|c| (0..n).map(|k| sim.masses()[k] * v[c * n + k]).sum())
}

#[test]
fn a_patch_acts_at_its_material_point_with_weights_summing_to_one_at_every_level() {
    let scene = free();
    for (nx, ny) in LEVELS {
        let sim = at(&scene, nx, ny);
        let shape = sim.topology().grid.expect("a grid");
        for patch in [
            Patch {
                u: 0.3,
                v: 0.6,
                radius: 0.1,
            },
            Patch {
                u: 0.77,
                v: 0.11,
                radius: 0.0,
            },
            Patch {
                u: 0.5,
                v: 0.5,
                radius: 0.02,
            },
        ] {
            let (nodes, weights) = patch.weights(&shape);
            let total: f64 = weights.iter().sum();
            assert!(
                (total - 1.0).abs() < 1e-12,
                "{nx}x{ny} {patch:?}: weights sum to {total}"
            );
            // Horizontal rest shape: x = u·width, z = v·height.
            let rest = &sim.topology().rest_positions;
            let centre = [0, 2].map(|c| {
                nodes
                    .iter()
                    .zip(&weights)
                    .map(|(&k, &w)| w * rest[k as usize][c])
                    .sum::<f64>()
            });
            assert!(
                (centre[0] - patch.u * scene.width).abs() < 1e-12 && (centre[1] - patch.v * scene.height).abs() < 1e-12,
                "{nx}x{ny} {patch:?}: acts at {centre:?}"
            );
        }
    }
}

#[test]
fn an_impulse_gives_the_cloth_exactly_its_momentum_at_every_level() {
    let scene = free();
    let j = [0.01, 0.02, -0.005];
    for (nx, ny) in LEVELS {
        let mut sim = at(&scene, nx, ny);
        let mut touch = Touch::new(&scene);
        touch
            .apply(
                &Input::Impulse {
                    at: Patch {
                        u: 0.3,
                        v: 0.6,
                        radius: 0.1,
                    },
                    impulse: j,
                },
                &mut sim,
            )
            .expect("a modest impulse is accepted");
        let p = momentum(&sim);
        for c in 0..3 {
            assert!(
                (p[c] - j[c]).abs() < 1e-12,
                "{nx}x{ny}: momentum {p:?} after an impulse {j:?}"
            );
        }
    }
}

#[test]
fn a_grabbed_cloth_without_gravity_comes_to_rest_with_its_patch_on_the_target() {
    // The grab is the only external force but drag; at rest the drag is 0,
    // so the grab's force is 0: the patch sits exactly on its target.
    let scene = free();
    let mut sim = at(&scene, 24, 16);
    let mut touch = Touch::new(&scene);
    let at = Patch {
        u: 0.25,
        v: 0.75,
        radius: 0.05,
    };
    let target = [0.25 * 1.2 + 0.1, 0.2, 0.75 * 0.8 - 0.05];
    touch
        .apply(
            &Input::Grab {
                id: 7,
                at,
                target: Some(target),
                stiffness: 5.0,
                damping: 0.05,
            },
            &mut sim,
        )
        .expect("a soft grab is stable");
    // 12 s: the last motion, a slow swing damped by drag alone, loses its
    // kinetic energy with a time constant of about 12 s (2.9e-8 J at 8 s,
    // 1.1e-8 J at 20 s; measured 2026-12-03), and at 8 s the fastest node
    // was at 1e-3 m/s either side by rounding alone.
    for _ in 0..120_000 {
        assert!(sim.step().finite);
    }
    let grab = &sim.grabs()[0];
    let (x, v) = grab.patch(&sim.state().pos, &sim.state().vel);
    let off = (0..3).map(|c| (x[c] - target[c]).powi(2)).sum::<f64>().sqrt();
    assert!(off < 1e-4, "after 12 s the patch is {off} m from its target ({x:?})");
    let speed = sim.state().vel.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    assert!(
        speed < 1e-3 && v.iter().all(|x| x.abs() < 1e-3),
        "still moving at {speed} m/s"
    );
    // It really was pulled: the patch moved 0.23 m from its rest place.
    let r = &sim.topology().rest_positions;
    let rest = [0, 1, 2].map(|d| {
        grab.nodes
            .iter()
            .zip(&grab.weights)
            .map(|(&k, &w)| w * r[k as usize][d])
            .sum::<f64>()
    });
    let moved = (0..3).map(|c| (x[c] - rest[c]).powi(2)).sum::<f64>().sqrt();
    assert!(moved > 0.2, "the patch moved only {moved} m");
}

#[test]
fn a_grab_too_stiff_for_the_levels_dt_is_refused_and_the_bound_is_tight_where_the_grab_dominates() {
    let scene = free();
    let mut sim = at(&scene, 24, 16);
    let mut touch = Touch::new(&scene);
    let at = Patch {
        u: 0.5,
        v: 0.5,
        radius: 0.0,
    };
    let grab = |k: f64| Input::Grab {
        id: 1,
        at,
        target: Some([0.6, 0.1, 0.4]),
        stiffness: k,
        damping: 0.0,
    };
    let max = match touch.apply(&grab(1e9), &mut sim) {
        Err(TouchError::Unstable { max, .. }) => max,
        other => panic!("a 1e9 N/m grab at dt 1e-4 was not refused as unstable: {other:?}"),
    };
    assert!(sim.grabs().is_empty(), "a refused grab left a spring behind");
    let message = touch.apply(&grab(1e9), &mut sim).unwrap_err().to_string();
    assert!(
        message.contains("stiffness") && message.contains("stable up to"),
        "{message}"
    );
    // Just below the bound: stable. Well above it (forced past the check):
    // the grab's own mode k/m outruns dt and the level diverges.
    let mut below = sim.clone();
    touch
        .apply(&grab(0.9 * max), &mut below)
        .expect("0.9 of the bound is accepted");
    for _ in 0..5_000 {
        assert!(below.step().finite, "diverged at 0.9 of the stable bound {max} N/m");
    }
    let mut above = sim.clone();
    let mut forced = below.grabs().to_vec();
    forced[0].stiffness = 1.5 * max;
    above.set_grabs(forced).expect("valid values");
    let diverged = (0..5_000).any(|_| !above.step().finite);
    assert!(
        diverged,
        "1.5 × the bound {max} N/m did not diverge: the bound is not tight"
    );
}

#[test]
fn a_pin_move_takes_its_pins_linearly_to_the_offset_at_every_level() {
    let mut scene =
        Scene::from_toml(&format!("{FREE}\n[[pins]]\nnodes = {{ edge = \"top\" }}\n"), "<pinned>").expect("valid");
    scene.stability = StabilityCheck::Enforce;
    for (nx, ny) in LEVELS {
        let mut sim = at(&scene, nx, ny);
        let mut touch = Touch::new(&scene);
        for _ in 0..100 {
            sim.step();
        }
        let node = sim.loads().pins[0].node as usize;
        let before = sim.state().position(node);
        let offset = [0.0, 0.1, -0.02];
        touch
            .apply(
                &Input::MovePin {
                    pin: 0,
                    offset,
                    seconds: 0.5,
                },
                &mut sim,
            )
            .expect("pin 0 exists");
        assert_eq!(sim.state().position(node), before, "{nx}x{ny}: the pin jumped");
        for _ in 0..2_500 {
            sim.step();
        }
        let half = sim.state().position(node);
        let v = sim.state().velocity(node);
        for c in 0..3 {
            assert!(
                (half[c] - before[c] - 0.5 * offset[c]).abs() < 1e-9,
                "{nx}x{ny}: halfway at {half:?}"
            );
            assert!((v[c] - offset[c] / 0.5).abs() < 1e-9, "{nx}x{ny}: moving at {v:?}");
        }
        for _ in 0..5_000 {
            sim.step();
        }
        let end = sim.state().position(node);
        for c in 0..3 {
            assert!(
                (end[c] - before[c] - offset[c]).abs() < 1e-9,
                "{nx}x{ny}: ends at {end:?}"
            );
        }
        assert!(
            touch.active(sim.state().time),
            "a pin off its script is an active touch"
        );
        let err = touch
            .apply(
                &Input::MovePin {
                    pin: 1,
                    offset,
                    seconds: 0.5,
                },
                &mut sim,
            )
            .unwrap_err()
            .to_string();
        assert!(err.contains("move_pin.pin") && err.contains("1 pin sets"), "{err}");
    }
}

#[test]
fn a_level_switch_puts_the_same_grab_and_wind_on_the_new_level() {
    let scene = free();
    let mut fine = at(&scene, 24, 16);
    let mut touch = Touch::new(&scene);
    let at = Patch {
        u: 0.3,
        v: 0.4,
        radius: 0.05,
    };
    touch
        .apply(
            &Input::Grab {
                id: 3,
                at,
                target: Some([0.5, 0.3, 0.2]),
                stiffness: 4.0,
                damping: 0.01,
            },
            &mut fine,
        )
        .expect("stable");
    touch
        .apply(
            &Input::Wind {
                velocity: [0.0, 0.0, 3.0],
                gust: 0.3,
                gust_hz: 0.5,
            },
            &mut fine,
        )
        .expect("valid wind");
    let mut coarse = at_level(&scene, 13, 9);
    touch
        .resolve(&mut coarse)
        .expect("the grab is stable on the coarse level too");
    assert_eq!(coarse.loads().wind, fine.loads().wind);
    let (f, c) = (&fine.grabs()[0], &coarse.grabs()[0]);
    assert_eq!((f.target, f.stiffness, f.damping), (c.target, c.stiffness, c.damping));
    // The same material point: the patch's rest position agrees.
    let rest = |s: &Simulation, g: &lodcloth::sim::Grab| {
        let r = &s.topology().rest_positions;
        [0, 1, 2].map(|d| {
            g.nodes
                .iter()
                .zip(&g.weights)
                .map(|(&k, &w)| w * r[k as usize][d])
                .sum::<f64>()
        })
    };
    let (rf, rc) = (rest(&fine, f), rest(&coarse, c));
    assert!((0..3).all(|d| (rf[d] - rc[d]).abs() < 1e-12), "{rf:?} vs {rc:?}");
    assert_eq!(touch.grab_ids(), vec![3]);
}

/// A switch to a finer grid (lighter nodes) can make a held grab unstable
/// at the same dt: it is softened to 90 % of what the new level holds, kept
/// (same id, same target) and reported, and the new level stays stable.
#[test]
fn a_grab_too_stiff_for_the_new_level_is_softened_and_kept_at_a_switch() {
    let scene = free();
    let mut coarse = at(&scene, 13, 9);
    let mut touch = Touch::new(&scene);
    let point = Patch {
        u: 0.5,
        v: 0.5,
        radius: 0.0,
    };
    let grab = |k: f64| Input::Grab {
        id: 7,
        at: point,
        target: Some([0.6, 0.1, 0.4]),
        stiffness: k,
        damping: 0.0,
    };
    let max_coarse = match touch.apply(&grab(1e9), &mut coarse) {
        Err(TouchError::Unstable { max, .. }) => max,
        other => panic!("not refused: {other:?}"),
    };
    touch
        .apply(&grab(0.9 * max_coarse), &mut coarse)
        .expect("stable on the coarse level");
    let mut fine = at_level(&scene, 48, 32);
    let softened = touch.resolve(&mut fine).expect("kept, softened");
    assert_eq!(softened.len(), 1, "{softened:?}");
    let s = softened[0];
    assert_eq!((s.id, s.from), (7, 0.9 * max_coarse));
    assert!(s.to < s.from, "{s:?}");
    assert_eq!(touch.grab_ids(), vec![7]);
    assert_eq!(fine.grabs()[0].stiffness, s.to);
    assert_eq!(fine.grabs()[0].target, [0.6, 0.1, 0.4]);
    for _ in 0..5_000 {
        assert!(fine.step().finite, "the softened grab diverged");
    }
    // Forced at its old stiffness, the fine level diverges: the softening
    // was needed.
    let mut forced = at_level(&scene, 48, 32);
    let mut g = fine.grabs().to_vec();
    g[0].stiffness = s.from;
    forced.set_grabs(g).expect("valid values");
    assert!((0..5_000).any(|_| !forced.step().finite), "{s:?} was stable unsoftened");
}

fn at_level(scene: &Scene, nx: usize, ny: usize) -> Simulation {
    at(scene, nx, ny)
}

#[test]
fn bad_inputs_are_refused_naming_their_field_and_change_nothing() {
    let scene = free();
    let mut sim = at(&scene, 13, 9);
    let mut touch = Touch::new(&scene);
    let grab = |u: f64, k: f64| Input::Grab {
        id: 1,
        at: Patch { u, v: 0.5, radius: 0.0 },
        target: Some([0.0; 3]),
        stiffness: k,
        damping: 0.0,
    };
    let cases: Vec<(Input, &str)> = vec![
        (grab(1.5, 1.0), "grab.at.u"),
        (grab(f64::NAN, 1.0), "grab.at.u"),
        (grab(0.5, f64::NAN), "grab.stiffness"),
        (grab(0.5, -1.0), "grab.stiffness"),
        (
            Input::Move {
                id: 9,
                target: [0.0; 3],
            },
            "move.id",
        ),
        (Input::Release { id: 9 }, "release.id"),
        (
            Input::Move {
                id: 1,
                target: [f64::INFINITY, 0.0, 0.0],
            },
            "move.target.x",
        ),
        (
            Input::Wind {
                velocity: [0.0; 3],
                gust: 2.0,
                gust_hz: 1.0,
            },
            "wind.gust",
        ),
        (
            Input::Impulse {
                at: Patch {
                    u: 0.5,
                    v: 0.5,
                    radius: -1.0,
                },
                impulse: [0.0; 3],
            },
            "impulse.at.radius",
        ),
        (
            Input::Impulse {
                at: Patch {
                    u: 0.5,
                    v: 0.5,
                    radius: 0.0,
                },
                impulse: [0.0, 0.0, 500.0],
            },
            "impulse.impulse",
        ),
        (
            Input::MovePin {
                pin: 0,
                offset: [0.0; 3],
                seconds: 1.0,
            },
            "move_pin.pin",
        ),
    ];
    let state = sim.state().clone();
    for (input, field) in cases {
        let err = touch.apply(&input, &mut sim).expect_err(field).to_string();
        assert!(err.starts_with(field), "{input:?}: '{err}' does not name {field}");
        assert_eq!(sim.state(), &state, "{input:?} changed the state");
        assert!(
            sim.grabs().is_empty() && sim.loads().wind.is_none(),
            "{input:?} left a load"
        );
    }
    assert!(!touch.active(0.0));
}

/// The standard drags behind a level's prediction under input
/// (`estimate::touched::probes`), worked out by hand from the rule for a
/// 1.2 × 0.8 m cloth pinned along its top edge under gravity: the three
/// free candidates farthest from the pinned nodes and from each other are
/// the bottom edge's middle (on 24 columns no pinned node lies exactly
/// above it, so it is a hair farther than the corners), then the
/// bottom-left corner (tied with the bottom-right at 0.6 m, first in row
/// order), then the bottom-right; the hand closes at
/// the frame nearest a fifth of the span, with the cloth's weight over 5 %
/// of √(W·H) as its stiffness, carries the patch 0.3 √(W·H) up (against
/// gravity: out of the horizontal rest plane) and then as far towards the
/// middle along the width, and lets go.
#[test]
fn the_standard_drags_take_the_free_points_farthest_from_the_pins_and_carry_them_as_the_rule_says() {
    use lodcloth::estimate::{probes, RecordSpec, Reference};
    let text = FREE.replace("gravity = [0.0, 0.0, 0.0]", "gravity = [0.0, -9.81, 0.0]")
        + "\n[[pins]]\nnodes = { edge = \"top\" }\n";
    let scene = Scene::from_toml(&text, "<pinned, gravity>").expect("valid");
    let spec = RecordSpec {
        frames: 2000,
        metric_stride: 20,
        estimate_stride: 20,
        difference_span: 1,
    };
    let reference = Reference::record(scene.build().expect("builds"), spec, &mut |_, _| {}).expect("records");
    let drags = probes(&scene, &reference).expect("three drags");
    let names: Vec<&str> = drags
        .iter()
        .map(|p| p.name.split(',').next().expect("a name"))
        .collect();
    assert_eq!(names, ["u=0.5 v=1", "u=0 v=1", "u=1 v=1"]);

    let (w, h) = (1.2, 0.8);
    let size = f64::sqrt(w * h);
    let span = *reference.frame_times.last().expect("frames");
    let stiffness = w * h * 0.2 * 9.81 / (0.05 * size);
    for (p, towards_middle) in drags.iter().zip([-1.0, 1.0, -1.0]) {
        let events = p.script.events();
        let (
            t0,
            Input::Grab {
                stiffness: k, target, ..
            },
        ) = events[0]
        else {
            panic!("{}: starts with a grab", p.name)
        };
        assert!(
            (t0 - 0.2 * span).abs() <= 0.5 * 20.0 * 1e-4,
            "{}: grabs at {t0}",
            p.name
        );
        assert!((k - stiffness).abs() <= 1e-9 * stiffness, "{}: {k} N/m", p.name);
        assert_eq!(target, None, "{}: the hand closes where the patch is", p.name);
        let moves: Vec<[f64; 3]> = events
            .iter()
            .filter_map(|(_, i)| match i {
                Input::Move { target, .. } => Some(*target),
                _ => None,
            })
            .collect();
        // Two legs of 0.2 × span × 60 targets each.
        let per_leg = (0.2 * span * 60.0).round() as usize;
        assert_eq!(moves.len(), 2 * per_leg, "{}", p.name);
        // Where the reference has the patch at t0.
        let f0 = reference
            .frame_times
            .iter()
            .position(|&t| t == t0)
            .expect("t0 is a frame time");
        let shape = reference.topology.grid.expect("a grid");
        let at = match events[0].1 {
            Input::Grab { at, .. } => at,
            _ => unreachable!(),
        };
        let (nodes, weights) = at.weights(&shape);
        let n = shape.nx * shape.ny;
        let frame = &reference.frames[f0];
        let start = [0, 1, 2].map(|c| {
            nodes
                .iter()
                .zip(&weights)
                .map(|(&k, &wk)| wk * f64::from(frame[c * n + k as usize]))
                .sum::<f64>()
        });
        let up = moves[per_leg - 1];
        let across = moves[2 * per_leg - 1];
        let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|c| (a[c] - b[c]).abs() < 1e-9);
        assert!(
            close(up, [start[0], start[1] + 0.3 * size, start[2]]),
            "{}: leg 1 ends at {up:?}",
            p.name
        );
        assert!(
            close(across, [up[0] + towards_middle * 0.3 * size, up[1], up[2]]),
            "{}: leg 2 ends at {across:?}, from {up:?}",
            p.name
        );
        let (t_end, last) = events.last().expect("events");
        assert!(matches!(last, Input::Release { id: 1 }), "{}: lets go last", p.name);
        assert!(
            (t_end - (t0 + 0.6 * span)).abs() < 1e-9,
            "{}: lets go at {t_end}",
            p.name
        );
    }
}

/// The free cloth as a mesh cloth (issue 23): a 1.2 × 0.8 m near-equilateral
/// sheet of 4 cm edges in the x–z plane, UVs its material coordinates, the
/// same density, zero gravity and drag; `pins` appended to the scene.
fn free_mesh(pins: &str) -> (tempfile::TempDir, Scene) {
    let dir = tempfile::tempdir().expect("temp dir");
    let sheet = lodcloth::mesh::generate::sheet(1.2, 0.8, 0.04);
    std::fs::write(
        dir.path().join("sheet.obj"),
        lodcloth::mesh::generate::to_obj(&sheet, "sheet"),
    )
    .expect("mesh");
    let text = format!(
        "name = \"free-mesh\"\n[cloth]\nmesh = \"sheet.obj\"\nareal_density = 0.2\n\
         [material]\nstiffness = {{ stretch_u = 300.0, stretch_v = 300.0, shear = 40.0, bend_u = 0.02, bend_v = 0.02 }}\n\
         damping_time = 1e-4\n[simulation]\nintegrator = \"symplectic_euler\"\ndt = 1e-4\nduration = 10.0\n\
         gravity = [0.0, 0.0, 0.0]\ndrag = 2.0\n{pins}\n"
    );
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).expect("scene");
    let scene = Scene::load(&path).expect("a valid mesh scene");
    (dir, scene)
}

/// The reference mesh and two simplified levels of `scene`.
fn mesh_levels(scene: &Scene) -> [lodcloth::level::Level; 3] {
    let n = scene.mesh.as_ref().expect("a mesh cloth").reference.vertices();
    [n, n * 2 / 5, n / 6].map(lodcloth::level::Level::Vertices)
}

/// Σ wₖ rₖ of a patch's nodes on the rest shape.
fn rest_point(sim: &Simulation, nodes: &[u32], weights: &[f64]) -> [f64; 3] {
    let r = &sim.topology().rest_positions;
    [0, 1, 2].map(|d| nodes.iter().zip(weights).map(|(&k, &w)| w * r[k as usize][d]).sum())
}

/// On a mesh a point acts exactly where its material coordinates are (the
/// sheet's rest shape is affine in them, and barycentric weights reproduce
/// affine maps); a patch is the rest surface within its radius, its weights
/// sum to 1 and its first moment is its centre at every level, to the
/// resolution of its subdivision.
#[test]
fn a_patch_on_a_mesh_acts_at_its_material_point_at_every_level() {
    let (_dir, scene) = free_mesh("");
    for level in mesh_levels(&scene) {
        let sim = scene.build_level(level).expect("builds");
        let mesh = RestSurface::of(sim.topology()).expect("a mesh level");
        for patch in [
            Patch {
                u: 0.77,
                v: 0.11,
                radius: 0.0,
            },
            Patch {
                u: 0.3,
                v: 0.6,
                radius: 0.1,
            },
            Patch {
                u: 0.5,
                v: 0.5,
                radius: 0.03,
            },
        ] {
            let (nodes, weights) = patch.mesh_weights(mesh);
            let total: f64 = weights.iter().sum();
            assert!((total - 1.0).abs() < 1e-12, "{level} {patch:?}: weights sum to {total}");
            assert!(weights.iter().all(|&w| w > 0.0), "{level} {patch:?}: {weights:?}");
            let at = rest_point(&sim, &nodes, &weights);
            let want = [patch.u * 1.2, 0.0, patch.v * 0.8];
            let off = (0..3).map(|d| (at[d] - want[d]).powi(2)).sum::<f64>().sqrt();
            // A point: exact. A disc: its pieces are r/12 across, and the
            // ring they straddle moves the centroid by a small part of that.
            let tolerance = if patch.radius == 0.0 {
                1e-12
            } else {
                patch.radius / 100.0
            };
            assert!(
                off < tolerance,
                "{level} {patch:?}: acts at {at:?}, {off} m from {want:?}"
            );
            if patch.radius > 0.0 {
                // Every node of the patch is within the radius plus one
                // triangle of the centre, and more than three carry it.
                assert!(nodes.len() > 3, "{level} {patch:?}: {} nodes", nodes.len());
            }
        }
    }
}

#[test]
fn an_impulse_on_a_mesh_gives_the_cloth_exactly_its_momentum_at_every_level() {
    let (_dir, scene) = free_mesh("");
    let j = [0.01, 0.02, -0.005];
    for level in mesh_levels(&scene) {
        let mut sim = scene.build_level(level).expect("builds");
        Touch::new(&scene)
            .apply(
                &Input::Impulse {
                    at: Patch {
                        u: 0.3,
                        v: 0.6,
                        radius: 0.1,
                    },
                    impulse: j,
                },
                &mut sim,
            )
            .expect("a modest impulse is accepted");
        let p = momentum(&sim);
        assert!((0..3).all(|c| (p[c] - j[c]).abs() < 1e-12), "{level}: momentum {p:?}");
    }
}

/// A grab on a mesh level holds its patch on the target at rest (the only
/// force but drag), and a switch to another level puts the same grab on the
/// same material point.
#[test]
fn a_grabbed_mesh_cloth_comes_to_rest_on_the_target_and_the_grab_survives_a_switch() {
    let (_dir, scene) = free_mesh("");
    let [_, fine_level, coarse_level] = mesh_levels(&scene);
    let mut sim = scene.build_level(coarse_level).expect("builds");
    let mut touch = Touch::new(&scene);
    let at = Patch {
        u: 0.25,
        v: 0.75,
        radius: 0.08,
    };
    let target = [0.25 * 1.2 + 0.1, 0.2, 0.75 * 0.8 - 0.05];
    touch
        .apply(
            &Input::Grab {
                id: 7,
                at,
                target: Some(target),
                stiffness: 5.0,
                damping: 0.05,
            },
            &mut sim,
        )
        .expect("a soft grab is stable");
    for _ in 0..80_000 {
        assert!(sim.step().finite);
    }
    let grab = sim.grabs()[0].clone();
    let (x, _) = grab.patch(&sim.state().pos, &sim.state().vel);
    let off = (0..3).map(|c| (x[c] - target[c]).powi(2)).sum::<f64>().sqrt();
    assert!(off < 1e-4, "after 8 s the patch is {off} m from its target ({x:?})");
    let rest = rest_point(&sim, &grab.nodes, &grab.weights);
    let moved = (0..3).map(|c| (x[c] - rest[c]).powi(2)).sum::<f64>().sqrt();
    assert!(moved > 0.2, "the patch moved only {moved} m");

    let mut fine = scene.build_level(fine_level).expect("builds");
    touch.resolve(&mut fine).expect("the grab is stable on the finer level");
    let g = &fine.grabs()[0];
    assert_eq!((g.target, g.stiffness), (target, 5.0));
    let there = rest_point(&fine, &g.nodes, &g.weights);
    let apart = (0..3).map(|c| (there[c] - rest[c]).powi(2)).sum::<f64>().sqrt();
    assert!(
        apart < at.radius / 50.0,
        "the same material point: {there:?} vs {rest:?}"
    );
}

/// A pin set of a mesh scene moves as a whole: every pinned vertex of the
/// set follows the move (and the scene's other set stays).
#[test]
fn a_pin_move_on_a_mesh_takes_its_set_and_only_its_set() {
    let (_dir, scene) = free_mesh("[[pins]]\nnodes = { edge = \"top\" }\n[[pins]]\nnodes = { vertices = [40] }");
    let mut sim = scene.build_level(mesh_levels(&scene)[1]).expect("builds");
    let before = sim.state().clone();
    let offset = [0.0, 0.1, -0.02];
    Touch::new(&scene)
        .apply(
            &Input::MovePin {
                pin: 0,
                offset,
                seconds: 0.1,
            },
            &mut sim,
        )
        .expect("pin set 0 exists");
    for _ in 0..1_500 {
        sim.step();
    }
    let (mut moved, mut kept) = (0, 0);
    for p in &sim.loads().pins {
        let k = p.node as usize;
        let (a, b) = (before.position(k), sim.state().position(k));
        let d: Vec<f64> = (0..3).map(|c| b[c] - a[c]).collect();
        if (0..3).all(|c| (d[c] - offset[c]).abs() < 1e-9) {
            moved += 1;
        } else {
            assert!(d.iter().all(|x| x.abs() < 1e-12), "pin {k} moved by {d:?}");
            kept += 1;
        }
    }
    assert_eq!(kept, 1, "the vertex pin stays");
    assert!(moved > 10, "the top edge moved: {moved} pins");
}

/// The standard drags on a mesh cloth follow the grid's rule: on the same
/// flat sheet pinned along its top they take the three bottom points, the
/// hand holds the cloth's weight at 5 % of √A, and each carries its patch
/// 0.3 √A up against gravity, then 0.3 √A across towards the middle in u.
#[test]
fn the_standard_drags_on_a_mesh_follow_the_grids_rule() {
    use lodcloth::estimate::{probes, RecordSpec, Reference};
    let (_dir, scene) = free_mesh("[[pins]]\nnodes = { edge = \"top\" }");
    let mut scene = scene;
    scene.params.gravity = [0.0, -9.81, 0.0];
    let spec = RecordSpec {
        frames: 1000,
        metric_stride: 20,
        estimate_stride: 20,
        difference_span: 1,
    };
    let reference = Reference::record(scene.build().expect("builds"), spec, &mut |_, _| {}).expect("records");
    let drags = probes(&scene, &reference).expect("three drags");
    let mut names: Vec<&str> = drags
        .iter()
        .map(|p| p.name.split(',').next().expect("a name"))
        .collect();
    names.sort_unstable();
    assert_eq!(names, ["u=0 v=1", "u=0.5 v=1", "u=1 v=1"]);
    let area = scene.mesh.as_ref().expect("a mesh").area;
    assert!((area - 1.2 * 0.8).abs() < 1e-9, "the sheet's area {area}");
    let size = area.sqrt();
    let stiffness = area * 0.2 * 9.81 / (0.05 * size);
    let span = *reference.frame_times.last().expect("frames");
    let per_leg = (0.2 * span * 60.0).round() as usize;
    for p in &drags {
        let events = p.script.events();
        let (t0, Input::Grab { stiffness: k, at, .. }) = events[0] else {
            panic!("{}: starts with a grab", p.name)
        };
        assert!((k - stiffness).abs() <= 1e-9 * stiffness, "{}: {k} N/m", p.name);
        assert!(
            (at.radius - 0.05 * size).abs() < 1e-12,
            "{}: radius {}",
            p.name,
            at.radius
        );
        let moves: Vec<[f64; 3]> = events
            .iter()
            .filter_map(|(_, i)| match i {
                Input::Move { target, .. } => Some(*target),
                _ => None,
            })
            .collect();
        assert_eq!(moves.len(), 2 * per_leg, "{}", p.name);
        let f0 = reference
            .frame_times
            .iter()
            .position(|&t| t == t0)
            .expect("t0 is a frame time");
        let (nodes, weights) = at.on(&reference.topology).expect("a mesh");
        let n = reference.topology.n_nodes;
        let frame = &reference.frames[f0];
        let start = [0, 1, 2].map(|c| {
            nodes
                .iter()
                .zip(&weights)
                .map(|(&k, &wk)| wk * f64::from(frame[c * n + k as usize]))
                .sum::<f64>()
        });
        let towards_middle = if at.u < 0.25 { 1.0 } else { -1.0 };
        let (up, across) = (moves[per_leg - 1], moves[2 * per_leg - 1]);
        let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|c| (a[c] - b[c]).abs() < 1e-9);
        assert!(
            close(up, [start[0], start[1] + 0.3 * size, start[2]]),
            "{}: leg 1 ends at {up:?}, from {start:?}",
            p.name
        );
        assert!(
            close(across, [up[0] + towards_middle * 0.3 * size, up[1], up[2]]),
            "{}: leg 2 ends at {across:?}, from {up:?}",
            p.name
        );
    }
}
