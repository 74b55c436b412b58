//! What the inverse fits see on a level: the strain of the reference's own
//! springs against that of the level's springs through the mapped
//! reference (coarse chords across folds the level does not resolve read
//! shorter than the material: estimate/inverse.rs, "Mesh levels"), the
//! aggregate correlation of the observed spring force with each class's
//! unit-stiffness basis, and BCD, GKD and `lsq` with their eq. 9 errors
//! against `same`'s over the recording.
//!
//! `cargo run --release -p lodcloth-lab --example inverse_diag -- SCENE LEVEL [STEPS]`
//!
//! LEVEL as the experiments take it (N, NXxNY, Nv, P%); STEPS of the
//! reference to record (default: the scene's duration), at the scene's
//! integrator and dt, which the level also runs at.
use std::sync::Arc;

use lodcloth_core::estimate::inverse::{observe, Bases};
use lodcloth_core::estimate::reference::Reference;
use lodcloth_core::estimate::{no_progress, FitOptions, LodProblem, Method, RecordSpec};
use lodcloth_core::level::GridLevel;
use lodcloth_core::scene::{MassConvention, Scene};
use lodcloth_core::sim::Topology;

fn strains(topo: &Topology, pos: &[f64], class: usize) -> Vec<f64> {
    let n = topo.n_nodes;
    let mut out = Vec::new();
    for g in topo.groups.iter().filter(|g| g.class.index() == class) {
        for s in 0..g.len() {
            let (a, b) = (g.a[s] as usize, g.b[s] as usize);
            let d: f64 = (0..3)
                .map(|c| (pos[c * n + b] - pos[c * n + a]).powi(2))
                .sum::<f64>()
                .sqrt();
            out.push(d / g.rest[s] - 1.0);
        }
    }
    out
}

/// The spread of Van Gelder's per-edge stiffness `Σ A_t / L²` (the two
/// triangles on an interior edge) over the mean: how far one K per class is from a uniform
/// membrane on these triangles.
fn edge_quality(name: &str, topo: &Topology) {
    use std::collections::HashMap;
    let x = &topo.rest_positions;
    let mut area: HashMap<(u32, u32), (f64, u32)> = HashMap::new();
    for t in &topo.triangles {
        let ar = lodcloth_core::mesh::triangle_area(x, *t);
        for (p, q) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let e = area.entry((p.min(q), p.max(q))).or_default();
            e.0 += ar;
            e.1 += 1;
        }
    }
    let w: Vec<f64> = area
        .iter()
        .filter(|(_, &(_, triangles))| triangles == 2)
        .map(|(&(a, b), &(ar, _))| {
            let (p, q) = (x[a as usize], x[b as usize]);
            ar / ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2))
        })
        .collect();
    let mean = w.iter().sum::<f64>() / w.len() as f64;
    summary(
        &format!("{name} edge weight / mean"),
        w.iter().map(|v| v / mean - 1.0).collect(),
    );
}

fn summary(name: &str, mut v: Vec<f64>) {
    v.sort_by(f64::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p) as usize];
    let neg = v.iter().filter(|&&x| x < 0.0).count() as f64 / v.len() as f64;
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    println!(
        "{name:28} mean {:+.5} p10 {:+.5} p50 {:+.5} p90 {:+.5} compressed {:.1}%",
        mean,
        q(0.1),
        q(0.5),
        q(0.9),
        100.0 * neg
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: inverse_diag SCENE LEVEL [STEPS]");
        std::process::exit(2);
    }
    let scene = Scene::load(std::path::Path::new(&args[1])).expect("scene");
    let verts = scene.mesh.as_ref().map(|m| m.reference.vertices());
    let level = args[2]
        .parse::<GridLevel>()
        .expect("level")
        .on(scene.width, scene.height, verts)
        .expect("level of scene");
    let frames = args
        .get(3)
        .map_or_else(|| scene.steps(), |f| f.parse().expect("frames"));
    let spec = RecordSpec {
        frames,
        ..RecordSpec::PAPER
    };
    let reference = Arc::new(Reference::record(scene.build().expect("builds"), spec, &mut |_, _| {}).expect("records"));
    // At the scene's dt when the level is stable there, else as the daemon
    // runs it (the largest stable dt dividing the frame interval).
    let at_scene_dt = LodProblem::at(
        &scene,
        reference.clone(),
        level,
        MassConvention::Lumped,
        scene.params.integrator,
        scene.params.dt,
    )
    .expect("level");
    let stable = at_scene_dt
        .simulation(at_scene_dt.same_material())
        .expect("sim")
        .dt_limit()
        >= scene.params.dt;
    let p = if stable {
        at_scene_dt
    } else {
        lodcloth_core::plan::default_problem(&scene, &reference, level).expect("level")
    };
    println!("level {level} at dt {:.3e} s", p.dt);
    let same = p.same_material();
    println!("level {level}: same {:?}", same.springs.map(|s| s.k));
    for (name, topo) in [("reference", &*reference.topology), ("level", &**p.topology())] {
        edge_quality(name, topo);
        let areas = &topo.node_areas;
        let mean = areas.iter().sum::<f64>() / areas.len() as f64;
        let mut order: Vec<usize> = (0..areas.len()).collect();
        order.sort_by(|&a, &b| areas[a].total_cmp(&areas[b]));
        let shortest = |k: usize| {
            topo.groups
                .iter()
                .filter(|g| g.kind() == lodcloth_core::sim::SpringKind::Structural)
                .flat_map(|g| {
                    (0..g.len())
                        .filter(move |&s| g.a[s] as usize == k || g.b[s] as usize == k)
                        .map(move |s| g.rest[s])
                })
                .fold(f64::INFINITY, f64::min)
        };
        for &k in order.iter().take(4) {
            println!(
                "  {name}: vertex {k} area {:.3e} ({:.4} of mean), shortest edge {:.2} mm, at {:?}",
                areas[k],
                areas[k] / mean,
                1e3 * shortest(k),
                topo.rest_positions[k].map(|x| (x * 1e3).round() / 1e3)
            );
        }
    }
    let mut sim = p.simulation(same).expect("sim");
    let obs = observe(&reference, p.correlation(), &mut sim, &mut no_progress);
    // Strain distributions: reference springs vs coarse springs on mapped positions.
    for class in [0usize, 3] {
        let mut fine = Vec::new();
        let mut coarse = Vec::new();
        for o in &obs.samples {
            let s = &reference.samples[o.sample];
            fine.extend(strains(&reference.topology, &s.cur, class));
            coarse.extend(strains(p.topology(), &o.pos, class));
        }
        if fine.is_empty() {
            continue;
        }
        summary(&format!("class {class} reference"), fine);
        summary(&format!("class {class} coarse (mapped)"), coarse);
    }
    // Aggregate F·G with the observed force (lsq reading of observed forces).
    let n = p.topology().n_nodes;
    let mut bases = Bases::new(n);
    let mut fg = [0.0; 5];
    let mut gg = [0.0; 5];
    let mut ff = 0.0;
    let mut gsum = [0.0f64; 5];
    for o in &obs.samples {
        bases.compute(p.topology(), &o.pos, &o.vel);
        for k in (0..n).filter(|&k| obs.free[k]) {
            for c in 0..3 {
                let f = o.spring_force[c * n + k];
                ff += f * f;
                for t in 0..5 {
                    let g = bases.elastic[t][c * n + k];
                    fg[t] += f * g;
                    gg[t] += g * g;
                    gsum[t] += g;
                }
            }
        }
    }
    for t in [0usize, 3] {
        if gg[t] > 0.0 {
            println!(
                "class {t}: total observed F·G/|G|² = {:.4} (same {:.4}), corr {:.3}",
                fg[t] / gg[t],
                same.springs[t].k,
                fg[t] / (ff.sqrt() * gg[t].sqrt())
            );
        }
    }
    for m in [Method::Bcd, Method::Gkd, Method::Lsq] {
        let e = p
            .estimate(m, &FitOptions::default(), &mut no_progress)
            .expect("estimate");
        println!(
            "{m:?}: K {:?} C {:?}",
            e.material.springs.map(|s| (s.k * 1e3).round() / 1e3),
            e.material.springs.map(|s| (s.c * 1e6).round() / 1e6)
        );
        println!("   {}", lodcloth_core::plan::notes(&e.details));
        let err = p
            .score(e.material, 0..p.frames(), &mut no_progress)
            .map(|e| e.mean * 100.0);
        println!("   error {err:?} %");
    }
    let err = p.score(same, 0..p.frames(), &mut no_progress).map(|e| e.mean * 100.0);
    println!("same error {err:?} %");
    // `same` with its bend stiffness scaled: how much of what the
    // estimators gain is the level's bending alone.
    for f in [0.5, 0.25, 0.125, 1.0 / 16.0, 1.0 / 64.0] {
        let mut m = same;
        for t in [3, 4] {
            m.springs[t].k *= f;
        }
        let err = p.score(m, 0..p.frames(), &mut no_progress).map(|e| e.mean * 100.0);
        println!("same, bend K x {f}: error {err:?} %");
    }
}
