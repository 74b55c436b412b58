//! The drape coefficient of a scene's cloth over its support, at the
//! reference and at each level with `same` and BCD coefficients, over the
//! run: a physical measure of coherence apart from the eq. 9 error (see
//! `lodcloth_core::drape`). The support is the scene's first collider
//! seen from above (a box's top, a sphere's or capsule's widest section).
//!
//! `cargo bench -p lodcloth-core --bench drape -- [--scene FILE] [--levels 16,24,32,40] [--methods same,bcd] [--out DIR]`
//!
//! Levels as the experiments take them: N or NXxNY on a grid cloth, Nv or
//! P% on a mesh cloth (default 60%,40%,25%,15%).
//!
//! Prints a table (the coefficient at 1 s, 2 s and the end, and its largest
//! difference from the reference's at those times) and writes it as CSV,
//! one row per level, method and time.
use std::path::Path;

use lodcloth_core::drape::{drape_coefficient, shadow_area};
use lodcloth_core::estimate::{no_progress, FitOptions, Method, RecordSpec};
use lodcloth_core::level::{GridLevel, Level};
use lodcloth_core::plan::{default_problem, record_reference};
use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{Shape, Simulation};

const PIXEL: f64 = 1e-3;

fn arg<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(String::as_str)
}

/// The area of the support seen from above (m²).
fn support_area(shape: &Shape) -> f64 {
    match *shape {
        Shape::Cuboid { half_extents: e } => 4.0 * e[0] * e[2],
        Shape::Sphere { radius } => std::f64::consts::PI * radius * radius,
        Shape::Capsule { half_axis, radius } => {
            let horizontal = (half_axis[0].powi(2) + half_axis[2].powi(2)).sqrt();
            std::f64::consts::PI * radius * radius + 4.0 * horizontal * radius
        }
        Shape::Cylinder { radius, .. } => std::f64::consts::PI * radius * radius,
        Shape::Plane { .. } => panic!("a plane supports everything: no drape coefficient"),
    }
}

/// The coefficient of `sim` stepped from rest, at each of `times` (s).
fn over_time(mut sim: Simulation, times: &[f64], cloth: f64, support: f64) -> Vec<f64> {
    let dt = sim.params().dt;
    times
        .iter()
        .map(|&t| {
            while sim.state().time < t - 0.5 * dt {
                assert!(sim.step().finite, "diverged");
            }
            let pos = &sim.state().pos;
            drape_coefficient(shadow_area(&sim.topology().triangles, pos, PIXEL), cloth, support)
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    // `cargo bench` runs in this crate's directory: relative paths are the
    // repository's, as the docs write them.
    let file = root.join(arg(&args, "--scene").unwrap_or("config/scenes/tablecloth-over-table.toml"));
    let out = root.join(arg(&args, "--out").unwrap_or("out/drape"));
    let scene = Scene::load(&file).expect("scene");
    let mesh_vertices = scene.mesh.as_ref().map(|m| m.reference.vertices());
    let levels: Vec<Level> = arg(&args, "--levels")
        .unwrap_or(if mesh_vertices.is_some() {
            "60%,40%,25%,15%"
        } else {
            "16,24,32,40"
        })
        .split(',')
        .map(|s| {
            let l: GridLevel = s.parse().expect("--levels: N, NXxNY, Nv or P%");
            l.on(scene.width, scene.height, mesh_vertices)
                .expect("a level of this scene")
        })
        .collect();
    let methods: Vec<Method> = arg(&args, "--methods")
        .unwrap_or("same,bcd")
        .split(',')
        .map(|s| Method::from_name(s).expect("--methods: same, bcd, gkd, lsq, fit"))
        .collect();
    let body = scene
        .colliders()
        .first()
        .expect("a scene with a support (its first collider)");
    let cloth = scene.mesh.as_ref().map_or(scene.width * scene.height, |m| m.area);
    let support = support_area(&body.shape);
    let mut times: Vec<f64> = [1.0, 2.0, scene.duration]
        .into_iter()
        .filter(|&t| t <= scene.duration)
        .collect();
    times.dedup();
    let spec = RecordSpec {
        frames: scene.steps(),
        ..RecordSpec::PAPER
    };
    eprintln!(
        "recording the {} reference over {} s …",
        scene.reference_level(),
        scene.duration
    );
    let (reference, _) = record_reference(&scene, spec, &mut |line| eprintln!("{line}")).expect("reference");
    let reference_dc = over_time(scene.build().expect("builds"), &times, cloth, support);
    let mut csv = String::from("level,method,time_s,drape_coefficient,reference,difference\n");
    println!(
        "scene {} (reference {}), support {:.4} m², cloth {:.4} m², shadow pixels {PIXEL} m",
        scene.name,
        scene.reference_level(),
        support,
        cloth
    );
    let heads: Vec<String> = times.iter().map(|t| format!("DC at {t} s")).collect();
    println!("| level | method | {} | largest |difference| |", heads.join(" | "));
    println!("|---|---|{}---|", "---|".repeat(times.len()));
    let row = |level: &str, method: &str, dc: &[f64], csv: &mut String| {
        let worst = dc
            .iter()
            .zip(&reference_dc)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        for ((t, d), r) in times.iter().zip(dc).zip(&reference_dc) {
            csv.push_str(&format!("{level},{method},{t},{d:.5},{r:.5},{:.5}\n", d - r));
        }
        let cells: Vec<String> = dc.iter().map(|d| format!("{d:.4}")).collect();
        println!("| {level} | {method} | {} | {worst:.4} |", cells.join(" | "));
    };
    row(
        &scene.reference_level().to_string(),
        "reference",
        &reference_dc,
        &mut csv,
    );
    for level in levels {
        let problem = default_problem(&scene, &reference, level).expect("a level");
        let label = format!("{level} ({} nodes)", problem.topology().n_nodes);
        for &method in &methods {
            let est = problem
                .estimate(method, &FitOptions::default(), &mut no_progress)
                .expect("estimates");
            let sim = problem.simulation(est.material).expect("builds");
            row(&label, method.name(), &over_time(sim, &times, cloth, support), &mut csv);
        }
    }
    std::fs::create_dir_all(&out).expect("output directory");
    std::fs::write(out.join("drape.csv"), csv).expect("drape.csv");
    eprintln!("wrote {}", out.join("drape.csv").display());
}
