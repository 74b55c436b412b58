//! Scratch probe: the quantile (shape) distance and eq. 9 of a level against
//! its reference, and its DC, as its bend class is scaled.
//! `cargo run --release -p lodcloth-core --example shape_probe -- SCENE LEVEL SCALES`
use lodcloth_core::drape::{drape_coefficient, shadow_area};
use lodcloth_core::estimate::RecordSpec;
use lodcloth_core::level::GridLevel;
use lodcloth_core::plan::{default_problem, record_reference};
use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{SpringClass, SpringKind};
use rayon::prelude::*;

const Q: usize = 64;

fn quantiles(values: &[f64], weights: &[f64], out: &mut Vec<f64>) {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let total: f64 = weights.iter().sum();
    let mut mids = Vec::with_capacity(values.len());
    let mut acc = 0.0;
    for &i in &order {
        mids.push((acc + 0.5 * weights[i]) / total);
        acc += weights[i];
    }
    let mut j = 0;
    for k in 0..Q {
        let q = (k as f64 + 0.5) / Q as f64;
        while j + 1 < mids.len() && mids[j + 1] < q {
            j += 1;
        }
        let v = if q <= mids[0] {
            values[order[0]]
        } else if j + 1 >= mids.len() {
            values[order[mids.len() - 1]]
        } else {
            let t = (q - mids[j]) / (mids[j + 1] - mids[j]);
            values[order[j]] + t * (values[order[j + 1]] - values[order[j]])
        };
        out.push(v);
    }
}

fn shape(pos: &[f64], masses: &[f64]) -> Vec<f64> {
    let n = masses.len();
    let mut out = Vec::with_capacity(3 * Q);
    for c in 0..3 {
        quantiles(&pos[c * n..(c + 1) * n], masses, &mut out);
    }
    out
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = Scene::load(std::path::Path::new(&args[1])).expect("scene");
    let level: GridLevel = args[2].parse().expect("level");
    let scales: Vec<f64> = args[3].split(',').map(|s| s.parse().unwrap()).collect();
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
    let support = std::f64::consts::PI * 0.09 * 0.09;
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
