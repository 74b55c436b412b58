//! The drape coefficient of a scene's cloth over its support, at the
//! reference and at each level with `same` and BCD coefficients, over the
//! run: a physical measure of coherence apart from the eq. 9 error (see
//! `lodcloth_core::drape`). The support is the scene's first collider
//! seen from above (a box's top, a sphere's or capsule's widest section).
//!
//! `cargo bench -p lodcloth-lab --bench drape -- [--scene FILE] [--levels 16,24,32,40] [--methods same,bcd] [--twins N] [--short-tolerance R] [--out DIR]`
//!
//! Levels as the experiments take them: N or NXxNY on a grid cloth, Nv or
//! P% on a mesh cloth (default 60%,40%,25%,15%).
//!
//! Prints a table (the coefficient at 1 s, 2 s and the end, and its largest
//! difference from the reference's at those times) and writes it as CSV,
//! one row per level, method and time (`drape.csv`).
//!
//! A second table (`shape.csv`) splits each level's eq. 9 error into what
//! the material decides and what the folds do: eq. 9 over the run and over
//! its last quarter; the difference of the drape's axisymmetric sag (mean
//! height by ring of rest distance from the support's axis, 10 rings, the
//! largest difference of a ring, % of O_max) at the end; and the folds
//! counted on the rim's outline at the end (`lodcloth_core::drape`).
//! `drape.svg` draws each drape at the end from above, as a tester sees it.
//!
//! `--twins N` runs each level and method N times more or less: the run
//! above and N − 1 twins with every node raised or lowered by a seeded
//! normal draw of 1 µm (`lodcloth_core::drape::jitter_heights`), and
//! prints the mean and spread of their DC at the end (`twins.csv`): one
//! run of a drape is one draw of its coefficient. The reference is one run.
use std::path::Path;

use lodcloth_core::drape::{drape_coefficient, fold_count, jitter_heights, ring_profile, shadow_area};
use lodcloth_core::estimate::{no_progress, Details, FitOptions, Method, RecordSpec};
use lodcloth_core::level::{GridLevel, Level};
use lodcloth_core::plan::{default_problem, record_reference};
use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{Shape, Simulation, SpringClass};
use rayon::prelude::*;

const PIXEL: f64 = 1e-3;

/// The vertical jitter of a twin (m), as `drape_scan`'s.
const TWIN_JITTER: f64 = 1e-6;

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

const RINGS: usize = 10;

/// The radius of the circle of the support's area seen from above (m).
fn support_radius(shape: &Shape) -> f64 {
    (support_area(shape) / std::f64::consts::PI).sqrt()
}

/// The coefficient of `sim` stepped from rest, at each of `times` (s), and
/// the drape at the last of them: its sag by ring and its folds.
fn over_time(mut sim: Simulation, times: &[f64], cloth: f64, support: f64, axis: [f64; 2]) -> (Vec<f64>, Drape) {
    let dt = sim.params().dt;
    let dc: Vec<f64> = times
        .iter()
        .map(|&t| {
            while sim.state().time < t - 0.5 * dt {
                assert!(sim.step().finite, "diverged");
            }
            let pos = &sim.state().pos;
            drape_coefficient(shadow_area(&sim.topology().triangles, pos, PIXEL), cloth, support)
        })
        .collect();
    let (rest, pos) = (&sim.topology().rest_positions, &sim.state().pos);
    let n = sim.topology().n_nodes;
    let drape = Drape {
        profile: ring_profile(rest, pos, axis, RINGS),
        folds: fold_count(rest, pos, axis),
        top: sim
            .topology()
            .triangles
            .iter()
            .map(|t| t.map(|k| [pos[k as usize] - axis[0], pos[2 * n + k as usize] - axis[1]]))
            .collect(),
        dc: *dc.last().expect("a time"),
    };
    (dc, drape)
}

/// A drape's shape at the end of a run.
struct Drape {
    /// Mean height by ring of rest distance (m).
    profile: Vec<f64>,
    /// Folds on the rim's outline.
    folds: usize,
    /// Its triangles seen from above, about the axis (x, z in m).
    top: Vec<[[f64; 2]; 3]>,
    /// Its drape coefficient.
    dc: f64,
}

/// Each drape from above, one panel per run, at one scale: the cloth's
/// triangles translucent (folded layers darker) over the support's outline.
fn drape_svg(panels: &[(String, &Drape)], reach: f64, support_radius: f64) -> String {
    const SIDE: f64 = 220.0;
    const COLUMNS: usize = 3;
    let rows = panels.len().div_ceil(COLUMNS);
    let scale = 0.45 * SIDE / reach;
    let mut svg = format!(
        "<svg xmlns='http://www.w3.org/2000/svg' width='{}' height='{}' font-family='sans-serif' font-size='12'>\n\
         <rect width='100%' height='100%' fill='white'/>\n",
        SIDE * COLUMNS as f64,
        (SIDE + 20.0) * rows as f64
    );
    for (i, (title, drape)) in panels.iter().enumerate() {
        let (x0, y0) = (
            SIDE * ((i % COLUMNS) as f64 + 0.5),
            (SIDE + 20.0) * (i / COLUMNS) as f64 + 20.0 + SIDE / 2.0,
        );
        svg.push_str(&format!(
            "<text x='{x0}' y='{}' text-anchor='middle'>{title}: {} folds, DC {:.3}</text>\n<g fill='#2f6db5' fill-opacity='0.25'>\n",
            y0 - SIDE / 2.0 - 4.0,
            drape.folds,
            drape.dc
        ));
        for t in &drape.top {
            let p: Vec<String> = t
                .iter()
                .map(|q| format!("{:.1},{:.1}", x0 + scale * q[0], y0 + scale * q[1]))
                .collect();
            svg.push_str(&format!("<polygon points='{}'/>\n", p.join(" ")));
        }
        svg.push_str(&format!(
            "</g>\n<circle cx='{x0}' cy='{y0}' r='{:.1}' fill='none' stroke='#c0392b' stroke-width='1'/>\n\
             <circle cx='{x0}' cy='{y0}' r='{:.1}' fill='none' stroke='#999' stroke-dasharray='3 3'/>\n",
            scale * support_radius,
            scale * reach
        ));
    }
    svg.push_str("</svg>\n");
    svg
}

impl Drape {
    /// The largest difference of a ring's mean height from `other`'s (m),
    /// over the rings both have nodes in.
    fn sag_difference(&self, other: &Drape) -> f64 {
        self.profile
            .iter()
            .zip(&other.profile)
            .map(|(a, b)| (a - b).abs())
            .filter(|d| d.is_finite())
            .fold(0.0, f64::max)
    }
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
    // `--short-tolerance X`: the fit guard's short-horizon ratio (default
    // 1.05; `inf` turns that check off, to see what the guard stops).
    let fit_options = FitOptions {
        short_tolerance: arg(&args, "--short-tolerance").map_or(FitOptions::default().short_tolerance, |t| {
            t.parse().expect("--short-tolerance: a ratio")
        }),
        ..FitOptions::default()
    };
    let twins: u64 = arg(&args, "--twins").map_or(1, |t| t.parse().expect("--twins: a count ≥ 1"));
    let methods: Vec<Method> = arg(&args, "--methods")
        .unwrap_or("same,bcd")
        .split(',')
        .map(|s| Method::from_name(s).expect("--methods: same, same_spring, bcd, gkd, lsq, fit, shape, follow, drape"))
        .collect();
    let body = scene
        .colliders()
        .first()
        .expect("a scene with a support (its first collider)");
    let cloth = scene.mesh.as_ref().map_or(scene.width * scene.height, |m| m.area);
    let support = support_area(&body.shape);
    // Every whole second (whether the drape has settled), and the end.
    let mut times: Vec<f64> = (1..=scene.duration.floor() as usize)
        .map(|t| t as f64)
        .chain([scene.duration])
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
    let axis = {
        let (centre, _) = body.at(scene.duration);
        [centre[0], centre[2]]
    };
    let (reference_dc, reference_drape) = over_time(scene.build().expect("builds"), &times, cloth, support, axis);
    let mut shape_csv =
        String::from("level,method,eq9_mean_pct,eq9_last_quarter_pct,sag_largest_ring_pct,folds,reference_folds\n");
    let mut drapes: Vec<(String, Drape)> = Vec::new();
    let mut shape_rows = vec![format!(
        "| {} | reference | — | — | — | {} |",
        scene.reference_level(),
        reference_drape.folds
    )];
    let mut csv = String::from("level,method,time_s,drape_coefficient,reference,difference\n");
    let mut twins_csv = String::from("level,method,twin,drape_coefficient_at_end\n");
    let mut twin_rows: Vec<String> = Vec::new();
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
                .estimate(method, &fit_options, &mut |p| {
                    if p.stage == "fit" {
                        eprintln!("{label} {}: iteration {}/{}", method.name(), p.done, p.total);
                    }
                })
                .expect("estimates");
            if let Details::Fit(r) = &est.details {
                let same = problem.same_material();
                // The classes the level has (a mesh cloth has no shear).
                let scales: Vec<String> = SpringClass::ALL
                    .iter()
                    .filter(|c| same.springs[c.index()].k > 0.0)
                    .map(|c| {
                        let (a, b) = (est.material.springs[c.index()], same.springs[c.index()]);
                        format!("{c:?} K×{:.3} C×{:.3}", a.k / b.k, a.c / b.c)
                    })
                    .collect();
                eprintln!(
                    "{label} {}: from {} ({:.3}% → {:.3}% training rms, {} runs, {}; short horizon {:.3}% → {:.3}%){}: {}",
                    method.name(),
                    r.start,
                    100.0 * r.start_rms,
                    100.0 * r.rms,
                    r.evaluations,
                    r.stop,
                    100.0 * r.short_start,
                    100.0 * r.short_fitted,
                    r.kept_start.as_ref().map_or(String::new(), |k| format!(" — {k}")),
                    scales.join(", ")
                );
            }
            let sim = problem.simulation(est.material).expect("builds");
            let (dc, drape) = over_time(sim, &times, cloth, support, axis);
            row(&label, method.name(), &dc, &mut csv);
            if twins > 1 {
                // The run above is twin 0; the others start 1 µm apart.
                let mut ends = vec![*dc.last().expect("a time")];
                ends.extend(
                    (1..twins)
                        .into_par_iter()
                        .map(|twin| {
                            let mut sim = problem.simulation(est.material).expect("builds");
                            jitter_heights(&mut sim, twin, TWIN_JITTER);
                            let end = [*times.last().expect("a time")];
                            over_time(sim, &end, cloth, support, axis).0[0]
                        })
                        .collect::<Vec<f64>>(),
                );
                for (twin, d) in ends.iter().enumerate() {
                    twins_csv.push_str(&format!("{level},{},{twin},{d:.5}\n", method.name()));
                }
                let mean = ends.iter().sum::<f64>() / ends.len() as f64;
                let sd = (ends.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (ends.len() - 1) as f64).sqrt();
                twin_rows.push(format!(
                    "| {label} | {} | {mean:.3} ± {sd:.3} | {:.3}–{:.3} |",
                    method.name(),
                    ends.iter().copied().fold(f64::INFINITY, f64::min),
                    ends.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                ));
            }
            let eq9 = problem
                .score(est.material, 0..problem.frames(), &mut no_progress)
                .expect("scores");
            let sag = 100.0 * drape.sag_difference(&reference_drape) / reference.o_max;
            shape_csv.push_str(&format!(
                "{level},{},{:.3},{:.3},{sag:.3},{},{}\n",
                method.name(),
                100.0 * eq9.mean,
                100.0 * eq9.last_quarter,
                drape.folds,
                reference_drape.folds
            ));
            shape_rows.push(format!(
                "| {label} | {} | {:.2} | {:.2} | {sag:.2} | {} |",
                method.name(),
                100.0 * eq9.mean,
                100.0 * eq9.last_quarter,
                drape.folds
            ));
            drapes.push((format!("{level} {}", method.name()), drape));
        }
    }
    if twins > 1 {
        println!();
        println!("| level | method | DC at the end over {twins} twins, mean ± sd | range |");
        println!("|---|---|---|---|");
        for r in &twin_rows {
            println!("{r}");
        }
        std::fs::create_dir_all(&out).expect("output directory");
        std::fs::write(out.join("twins.csv"), &twins_csv).expect("twins.csv");
    }
    println!();
    println!("| level | method | eq. 9 mean % | last quarter % | sag: largest ring difference, % of O_max | folds |");
    println!("|---|---|---|---|---|---|");
    for r in &shape_rows {
        println!("{r}");
    }
    std::fs::create_dir_all(&out).expect("output directory");
    std::fs::write(out.join("drape.csv"), csv).expect("drape.csv");
    std::fs::write(out.join("shape.csv"), shape_csv).expect("shape.csv");
    let reach = scene
        .build()
        .expect("builds")
        .topology()
        .rest_positions
        .iter()
        .map(|p| (p[0] - axis[0]).hypot(p[2] - axis[1]))
        .fold(0.0, f64::max);
    let mut panels = vec![(format!("{} reference", scene.reference_level()), &reference_drape)];
    panels.extend(drapes.iter().map(|(t, d)| (t.clone(), d)));
    std::fs::write(
        out.join("drape.svg"),
        drape_svg(&panels, reach, support_radius(&body.shape)),
    )
    .expect("drape.svg");
    eprintln!("wrote {}: drape.csv, shape.csv, drape.svg", out.display());
}
