//! Scene files: every shipped scene loads and builds at any resolution; an
//! invalid scene is refused with a message naming every offending field;
//! node masses follow the chosen convention at every resolution; loads and
//! pins resolve to the same physical quantities at every resolution.

use std::path::{Path, PathBuf};

use lodcloth::level::Level;
use lodcloth::scene::{MassConvention, Scene, SceneError};

/// Every `*.toml` in config/scenes/, sorted.
fn shipped_scenes() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no scene files in {}", dir.display());
    files
}

const RESOLUTIONS: [(usize, usize); 4] = [(16, 16), (40, 40), (100, 37), (7, 5)];

/// The levels a shipped scene is checked at: its own and [`RESOLUTIONS`] on
/// a grid cloth; every vertex, 40 % and 15 % of them on a mesh cloth.
fn levels_of(scene: &Scene) -> Vec<Level> {
    match &scene.mesh {
        Some(m) => {
            let n = m.reference.vertices();
            vec![
                Level::Vertices(n),
                Level::Vertices(n * 2 / 5),
                Level::Vertices(n * 3 / 20),
            ]
        }
        None => std::iter::once((scene.nx, scene.ny))
            .chain(RESOLUTIONS)
            .map(Level::from)
            .collect(),
    }
}

/// `scene` at `nx × ny`, at its dt or, where the level's cells are shorter
/// than the scene's along some axis (its springs are then stiffer: the same
/// material on shorter springs), at 0.8 of the level's stability limit.
fn build_stable(scene: &Scene, nx: usize, ny: usize) -> Result<lodcloth::sim::Simulation, lodcloth::scene::SceneError> {
    build_stable_at(scene, Level::new(nx, ny))
}

/// [`build_stable`] at any level (a mesh level's shortest edges set its limit).
fn build_stable_at(scene: &Scene, level: Level) -> Result<lodcloth::sim::Simulation, lodcloth::scene::SceneError> {
    let mut probe = scene.clone();
    probe.stability = lodcloth::sim::StabilityCheck::Force;
    let limit = probe.build_level(level)?.dt_limit();
    let mut s = scene.clone();
    s.params.dt = s.params.dt.min(0.8 * limit);
    s.build_level(level)
}

#[test]
fn every_shipped_scene_parses_validates_and_builds_at_its_own_and_other_resolutions() {
    for path in shipped_scenes() {
        let scene = Scene::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let levels = levels_of(&scene);
        for &level in &levels {
            let mut sim =
                build_stable_at(&scene, level).unwrap_or_else(|e| panic!("{} at {level}: {e}", path.display()));
            let n = sim.topology().n_nodes as f64;
            let asked = level.nodes() as f64;
            assert!(
                (n - asked).abs() <= lodcloth::mesh::VERTEX_TOLERANCE * asked,
                "{} at {level}: {n} nodes",
                path.display()
            );
            let held = !sim.loads().pins.is_empty() || !sim.loads().colliders.is_empty();
            assert!(held, "{}: no pin or body holds the cloth at {level}", path.display());
            // It really runs: a few steps stay finite.
            for _ in 0..5 {
                assert!(sim.step().finite, "{} at {level} diverged", path.display());
            }
        }
        eprintln!("{}: builds at {levels:?}", path.display());
    }
}

/// A valid scene to break in the tests below.
const VALID: &str = r#"
name = "valid"

[cloth]
width = 1.0
height = 0.5
nx = 12
ny = 6
areal_density = 0.2

[springs]
structural = { k = 400.0, c = 0.04 }
shear = { k = 60.0, c = 0.006 }
bend = { k = 8.0, c = 0.0008 }

[simulation]
integrator = "symplectic_euler"
dt = 1e-4
duration = 1.0

[[pins]]
nodes = { edge = "top" }

[[forces]]
nodes = { edge = "bottom" }
total = [0.0, -1.0, 0.0]
"#;

fn invalid_message(text: &str) -> String {
    match Scene::from_toml(text, "<test>") {
        Ok(_) => panic!("accepted an invalid scene:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn the_valid_template_is_valid() {
    let scene = Scene::from_toml(VALID, "<test>").expect("valid");
    scene.build().expect("builds");
}

#[test]
fn unknown_field_is_refused_with_its_name_and_line() {
    let text = VALID.replace("areal_density = 0.2", "areal_density = 0.2\ncolour = \"red\"");
    let err = Scene::from_toml(&text, "<test>").expect_err("unknown field");
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(matches!(err, SceneError::Parse { .. }));
    assert!(msg.contains("colour"), "{msg}");
    // The line of the offending key (line 9 of the text, counting from 1).
    let line = text.lines().position(|l| l.starts_with("colour")).expect("inserted") + 1;
    assert!(msg.contains(&format!("line {line}")), "{msg}");
}

#[test]
fn negative_stiffness_is_refused_naming_springs_structural_k() {
    let msg = invalid_message(&VALID.replace("structural = { k = 400.0", "structural = { k = -400.0"));
    assert!(msg.contains("springs.structural.k"), "{msg}");
}

/// Found by `parse_fuzz` (2026-11-26): a cloth of 1e-320 m by 5e-321 m
/// passed (positive, aspect 2:1), and the springs made at another level's
/// cells came out NaN (squared cell sizes underflow to 0).
#[test]
fn a_cloth_too_small_or_too_large_to_make_springs_is_refused_naming_its_size() {
    let tiny = VALID
        .replace("width = 1.0", "width = 1e-320")
        .replace("height = 0.5", "height = 5e-321");
    let msg = invalid_message(&tiny);
    assert!(msg.contains("cloth.width") && msg.contains("cloth.height"), "{msg}");
    let huge = VALID
        .replace("width = 1.0", "width = 1e300")
        .replace("height = 0.5", "height = 5e299");
    let msg = invalid_message(&huge);
    assert!(msg.contains("cloth.width") && msg.contains("cloth.height"), "{msg}");
}

#[test]
fn one_node_per_side_is_refused_naming_cloth_nx() {
    let msg = invalid_message(&VALID.replace("nx = 12", "nx = 1"));
    assert!(msg.contains("cloth.nx"), "{msg}");
    assert!(!msg.contains("cloth.ny"), "{msg}");
}

#[test]
fn bad_edge_name_is_refused_naming_its_pin() {
    let msg = invalid_message(&VALID.replace("edge = \"top\"", "edge = \"middle\""));
    assert!(msg.contains("pins[0].nodes.edge"), "{msg}");
    assert!(msg.contains("middle"), "{msg}");
}

/// An ellipse of the material square pins the nodes inside it: on a 5×5
/// grid (u, v steps of ¼) a disc of radius ¼ about the middle holds the
/// middle node and its four neighbours at exactly ¼, no diagonal (√2/4).
/// A radius that is not positive, or a centre that is not finite, is
/// refused naming the field.
#[test]
fn an_ellipse_pins_the_nodes_inside_it_and_a_bad_one_is_refused_naming_its_field() {
    let clamp = "ellipse = { center = [0.5, 0.5], radii = [0.25, 0.25] }";
    let text = VALID
        .replace("nx = 12", "nx = 5")
        .replace("ny = 6", "ny = 5")
        .replace("edge = \"top\"", clamp);
    let sim = Scene::from_toml(&text, "<test>")
        .expect("valid")
        .build()
        .expect("builds");
    let mut held: Vec<u32> = sim.loads().pins.iter().map(|p| p.node).collect();
    held.sort_unstable();
    // Node (i, j) is j·5 + i.
    assert_eq!(held, vec![7, 11, 12, 13, 17]);
    let msg = invalid_message(&text.replace("radii = [0.25, 0.25]", "radii = [0.0, 0.25]"));
    assert!(msg.contains("pins[0].nodes.ellipse.radii[0]"), "{msg}");
    let msg = invalid_message(&text.replace("center = [0.5, 0.5]", "center = [0.5, nan]"));
    assert!(msg.contains("pins[0].nodes.ellipse.center[1]"), "{msg}");
}

#[test]
fn several_problems_at_once_are_all_reported_with_their_paths() {
    let text = VALID
        .replace("structural = { k = 400.0", "structural = { k = -400.0")
        .replace("bend = { k = 8.0, c = 0.0008 }", "bend = { k = 8.0, c = -1.0 }")
        .replace("nx = 12", "nx = 1")
        .replace("edge = \"top\"", "edge = \"middle\"")
        .replace("edge = \"bottom\"", "corner = \"left-top\"")
        .replace("dt = 1e-4", "dt = -1e-4")
        .replace("areal_density = 0.2", "areal_density = 0.0");
    let err = Scene::from_toml(&text, "<test>").expect_err("invalid");
    let msg = err.to_string();
    eprintln!("{msg}");
    let paths = [
        "springs.structural.k",
        "springs.bend.c",
        "cloth.nx",
        "pins[0].nodes.edge",
        "forces[0].nodes.corner",
        "simulation.dt",
        "cloth.areal_density",
    ];
    for path in paths {
        assert!(msg.contains(path), "{path} missing from:\n{msg}");
    }
    match err {
        SceneError::Invalid { problems, .. } => assert_eq!(problems.len(), paths.len(), "{problems:#?}"),
        other => panic!("expected SceneError::Invalid, got {other:?}"),
    }
}

#[test]
fn building_at_one_node_per_side_is_refused() {
    let scene = Scene::from_toml(VALID, "<test>").expect("valid");
    let msg = scene
        .build_at(1, 5)
        .map(|_| ())
        .expect_err("1 node per side")
        .to_string();
    assert!(msg.contains("resolution.nx"), "{msg}");
}

fn with_mass(convention: &str) -> Scene {
    let text = VALID.replace(
        "areal_density = 0.2",
        &format!("areal_density = 0.2\nmass = \"{convention}\""),
    );
    Scene::from_toml(&text, "<test>").expect("valid")
}

#[test]
fn lumped_total_mass_is_areal_density_times_area_at_every_resolution() {
    let scene = with_mass("lumped");
    assert_eq!(scene.mass, MassConvention::Lumped);
    let expected = 0.2 * 1.0 * 0.5;
    for (nx, ny) in [(12, 6), (2, 2), (16, 16), (40, 40), (100, 37)] {
        let sim = build_stable(&scene, nx, ny).expect("builds");
        let total: f64 = sim.masses().iter().sum();
        assert!(
            (total - expected).abs() < 1e-12 * expected,
            "{nx}x{ny}: {total} kg vs {expected} kg"
        );
    }
}

#[test]
fn per_node_total_mass_is_proportional_to_the_node_count() {
    let scene = with_mass("per_node");
    assert_eq!(scene.mass, MassConvention::PerNode);
    // Each node weighs total / (12·6) at every resolution.
    let per_node = 0.2 * 1.0 * 0.5 / 72.0;
    for (nx, ny) in [(12, 6), (2, 2), (16, 16), (40, 40), (100, 37)] {
        let sim = build_stable(&scene, nx, ny).expect("builds");
        let total: f64 = sim.masses().iter().sum();
        let expected = per_node * (nx * ny) as f64;
        assert!(
            (total - expected).abs() < 1e-12 * expected,
            "{nx}x{ny}: {total} kg vs {expected} kg"
        );
        assert!(sim.masses().iter().all(|&m| m == sim.masses()[0]));
    }
}

/// Σ share · rest position over a load's nodes (shares sum to 1).
fn centre_of_load(sim: &lodcloth::sim::Simulation, load: &lodcloth::sim::NodeLoad) -> [f64; 3] {
    let mut c = [0.0; 3];
    for (&k, &w) in load.nodes.iter().zip(&load.shares) {
        let p = sim.topology().rest_positions[k as usize];
        for d in 0..3 {
            c[d] += w * p[d];
        }
    }
    c
}

#[test]
fn loads_and_pins_resolve_to_the_same_physical_quantities_at_every_resolution() {
    for path in shipped_scenes() {
        let scene = Scene::load(&path).expect("loads");
        let reference = scene.build().expect("builds");
        let totals = |sim: &lodcloth::sim::Simulation| -> Vec<[f64; 3]> {
            sim.loads()
                .forces
                .iter()
                .map(|l| {
                    let s: f64 = l.shares.iter().sum();
                    l.force.map(|f| f * s)
                })
                .collect()
        };
        let expected = totals(&reference);
        for level in levels_of(&scene) {
            let sim = build_stable_at(&scene, level).expect("builds");
            let got = totals(&sim);
            assert_eq!(got.len(), expected.len());
            for (g, e) in got.iter().zip(&expected) {
                for c in 0..3 {
                    assert!(
                        (g[c] - e[c]).abs() < 1e-12,
                        "{}: {g:?} vs {e:?} at {level}",
                        path.display()
                    );
                }
            }
            // Each load acts at the same point of the cloth (its centre of
            // load in the rest shape) at every resolution: an edge at its
            // middle, a region at the patch's centre, even where the
            // patch is smaller than a cell.
            for (l, r) in sim.loads().forces.iter().zip(&reference.loads().forces) {
                let (a, b) = (centre_of_load(&sim, l), centre_of_load(&reference, r));
                for c in 0..3 {
                    assert!(
                        (a[c] - b[c]).abs() < 1e-9,
                        "{}: centre of load {a:?} at {level}, {b:?} at the reference",
                        path.display()
                    );
                }
            }
            // Pins sit at their nodes' rest positions.
            for pin in &sim.loads().pins {
                assert_eq!(pin.anchor, sim.topology().rest_positions[pin.node as usize]);
            }
        }
    }
    // An edge pins a whole side at any resolution, a corner one node.
    let scene = Scene::from_toml(VALID, "<test>").expect("valid");
    for (nx, ny) in RESOLUTIONS {
        let sim = build_stable(&scene, nx, ny).expect("builds");
        assert_eq!(sim.loads().pins.len(), nx, "top edge at {nx}x{ny}");
        assert!(sim.loads().pins.iter().all(|p| (p.node as usize) < nx));
    }
}

/// `same` on square cells of a square-celled scene is the scene's springs,
/// bit for bit, at every level (and on any cells at the scene's own
/// resolution): a round trip through the membrane would change the last
/// bits, and a long run of a falling cloth turns that into percents.
#[test]
fn square_levels_of_a_square_celled_scene_keep_its_springs_bit_for_bit() {
    let mut checked = 0;
    for path in shipped_scenes() {
        let scene = Scene::load(&path).unwrap();
        if scene.mesh.is_some() {
            continue; // a grid's property
        }
        let own = scene.material_at(scene.nx, scene.ny);
        assert_eq!(own, scene.params.material, "{}: own resolution", path.display());
        let shape = scene.shape(scene.nx, scene.ny);
        if shape.hx() != shape.hy() {
            continue;
        }
        for n in [12, 24, 40, 48, 60] {
            let level = scene.shape(n, n);
            if level.hx() == level.hy() {
                assert_eq!(
                    scene.material_at(n, n),
                    scene.params.material,
                    "{} at {n}×{n}",
                    path.display()
                );
                checked += 1;
            }
        }
    }
    assert!(checked >= 15, "only {checked} square levels checked");
}
