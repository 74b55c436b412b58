//! The landscape of a `shape` fit along one coefficient: a level of a
//! Cusick scene run from rest with its bend class (K and C) scaled by each
//! factor, and its shape error (the RMS of the mass-weighted quantile
//! differences per coordinate, % of O_max) and mean eq. 9 error against
//! the reference, over the training half and the whole run, every 20th
//! metric frame, and its drape coefficient at the end. What
//! `estimate/fit.rs`'s `BEND_LADDER` and `SHAPE_FD_STEP` are chosen from.
//!
//! `cargo run --release -p lodcloth-lab --example shape_probe -- config/scenes/cusick-drape.toml 60% 0.7,1,1.2,1.35,1.5,2`
use lodcloth_core::drape::{drape_coefficient, shadow_area};
use lodcloth_core::estimate::fit::{shape_quantiles, ShapeScratch, SHAPE_QUANTILES};
use lodcloth_core::estimate::RecordSpec;
use lodcloth_core::level::GridLevel;
use lodcloth_core::plan::{default_problem, record_reference};
use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{Shape, SpringClass, SpringKind};
use rayon::prelude::*;

/// The mass-weighted quantiles of each coordinate (the `shape` fit's).
fn shape(pos: &[f64], masses: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(3 * SHAPE_QUANTILES);
    shape_quantiles(pos, masses, &mut ShapeScratch::default(), &mut out);
    out
}

fn main() {
    const USAGE: &str = "usage: shape_probe SCENE LEVEL SCALE[,SCALE…]";
    let args: Vec<String> = std::env::args().collect();
    let [_, scene, level, scales] = args.as_slice() else {
        panic!("{USAGE}")
    };
    let scene = Scene::load(std::path::Path::new(scene)).expect("the scene");
    let level: GridLevel = level.parse().expect("LEVEL: N, NXxNY, Nv or P%");
    let scales: Vec<f64> = scales
        .split(',')
        .map(|s| s.parse().expect("SCALES: numbers, comma-separated"))
        .collect();
    let spec = RecordSpec {
        frames: scene.steps(),
        ..RecordSpec::PAPER
    };
    let (reference, _) = record_reference(&scene, spec, &mut |l| eprintln!("{l}")).expect("reference");
    let mesh_vertices = scene.mesh.as_ref().map(|m| m.reference.vertices());
    let level = level.on(scene.width, scene.height, mesh_vertices).unwrap();
    let problem = default_problem(&scene, &reference, level).expect("problem");
    let n = problem.topology().n_nodes;
    let masses = problem.masses().to_vec();
    let frames = reference.frames.len();
    let stride = 20;
    let targets: Vec<(Vec<f64>, Vec<f64>)> = (0..frames)
        .step_by(stride)
        .map(|f| {
            let mut m = vec![0.0; 3 * n];
            problem.correlation().map(&reference.frames[f], &mut m);
            let s = shape(&m, &masses);
            (m, s)
        })
        .collect();
    let cloth = scene.mesh.as_ref().unwrap().area;
    let support = match scene.colliders().first().map(|b| b.shape) {
        Some(Shape::Cylinder { radius, .. }) => std::f64::consts::PI * radius * radius,
        other => panic!("a Cusick scene's support is a cylinder, not {other:?}"),
    };
    let o = reference.o_max;
    let rows: Vec<String> = scales
        .par_iter()
        .map(|&s| {
            let mut m = problem.same_material();
            for class in SpringClass::ALL {
                if class.kind() == SpringKind::Bend {
                    m.springs[class.index()].k *= s;
                    m.springs[class.index()].c *= s;
                }
            }
            let mut sim = problem.simulation(m).unwrap();
            let (mut q_train, mut q_all, mut e_train, mut e_all) = (0.0, 0.0, 0.0, 0.0);
            let half = targets.len() / 2;
            for (k, (t, ts)) in targets.iter().enumerate() {
                let time = reference.frame_times[k * stride];
                while sim.state().time < time - 0.5 * problem.dt {
                    sim.step();
                }
                let pos = &sim.state().pos;
                let qs = shape(pos, &masses);
                let q: f64 = qs.iter().zip(ts).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / qs.len() as f64;
                let e: f64 = (0..n)
                    .map(|i| {
                        (0..3)
                            .map(|c| (pos[c * n + i] - t[c * n + i]).powi(2))
                            .sum::<f64>()
                            .sqrt()
                    })
                    .sum::<f64>()
                    / n as f64;
                q_all += q;
                e_all += e;
                if k < half {
                    q_train += q;
                    e_train += e;
                }
            }
            let nt = targets.len() as f64;
            let dc = drape_coefficient(
                shadow_area(&sim.topology().triangles, &sim.state().pos, 1e-3),
                cloth,
                support,
            );
            format!(
                "{level} ×{s}: shape rms train {:.3}% all {:.3}% | eq9 train {:.3}% all {:.3}% | DC {dc:.3}",
                100.0 * (q_train / half as f64).sqrt() / o,
                100.0 * (q_all / nt).sqrt() / o,
                100.0 * e_train / half as f64 / o,
                100.0 * e_all / nt / o
            )
        })
        .collect();
    for r in rows {
        println!("{r}");
    }
}
