//! The spring kernel in f64 and in f32, on every vector path this CPU has,
//! in one run: what f32 buys per spring before any step uses it (issue 21's
//! f32 live path). One evaluation of every spring of the 64×64 hanging
//! fabric (structural, shear, bend) at a state 0.2 s into the scene, the
//! same positions rounded to f32; the paths and precisions interleaved
//! batch by batch, the fastest of `--batches` batches of 2,000 evaluations
//! each. Prints µs per evaluation, ns per spring and the f64/f32 ratio,
//! and checks that f32's forces stay within a bound of f64's.
//!
//! `cargo bench -p lodcloth-core --bench precision -- [--batches 9] [--size 64]`
use std::sync::Arc;
use std::time::Instant;

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{active_isa_name, force_path, SpringKernel, VectorPath};

const SCENE: &str = include_str!("../../../config/scenes/hanging.toml");

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let batches: usize = arg("--batches").map_or(9, |s| s.parse().expect("--batches: a count"));
    let size: usize = arg("--size").map_or(64, |s| s.parse().expect("--size: nodes a side"));
    let mut scene = Scene::from_toml(SCENE, "hanging.toml").expect("shipped scene is valid");
    scene.params.strain_limit = None;
    scene.params.stiffness_adjustment = None;
    let mut sim = scene.build_at(size, size).expect("builds");
    while sim.state().time < 0.2 {
        sim.step();
    }
    let topology = Arc::clone(sim.topology());
    let material = sim.params().material;
    let springs = topology.spring_count();
    let (pos, vel) = (sim.state().pos.clone(), sim.state().vel.clone());
    let (pos32, vel32): (Vec<f32>, Vec<f32>) = (
        pos.iter().map(|&x| x as f32).collect(),
        vel.iter().map(|&x| x as f32).collect(),
    );
    let mut k64 = SpringKernel::<f64>::new(topology.clone());
    let mut k32 = SpringKernel::<f32>::new(topology.clone());
    let mut f64s = vec![0.0f64; pos.len()];
    let mut f32s = vec![0.0f32; pos.len()];

    // What f32 changes: the largest force difference against the largest force.
    k64.add_forces(&material, None, &pos, &vel, &mut f64s);
    k32.add_forces(&material, None, &pos32, &vel32, &mut f32s);
    let scale = f64s.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    let worst = f64s
        .iter()
        .zip(&f32s)
        .fold(0.0f64, |m, (a, b)| m.max((a - f64::from(*b)).abs()));
    println!(
        "{size}×{size} hanging fabric at t = {:.2} s, {springs} springs; f32 forces differ from f64 by at most {:.2e} of the largest force",
        sim.state().time,
        worst / scale
    );
    assert!(
        worst / scale < 1e-3,
        "f32 forces off by {:.2e} of the largest",
        worst / scale
    );

    let mut paths = vec![("best", VectorPath::Best)];
    for (name, path) in [("avx2", VectorPath::Avx2), ("baseline", VectorPath::Baseline)] {
        force_path(path);
        let isa = active_isa_name();
        force_path(VectorPath::Best);
        if paths.iter().all(|(_, p)| {
            force_path(*p);
            let other = active_isa_name();
            force_path(VectorPath::Best);
            other != isa
        }) {
            paths.push((name, path));
        }
    }
    const EVALS: usize = 2000;
    let mut best = vec![[f64::INFINITY; 2]; paths.len()];
    for _ in 0..batches {
        for (p, (_, path)) in paths.iter().enumerate() {
            force_path(*path);
            let t = Instant::now();
            for _ in 0..EVALS {
                f64s.fill(0.0);
                std::hint::black_box(k64.add_forces(&material, None, &pos, &vel, &mut f64s));
            }
            best[p][0] = best[p][0].min(t.elapsed().as_secs_f64() / EVALS as f64);
            let t = Instant::now();
            for _ in 0..EVALS {
                f32s.fill(0.0);
                std::hint::black_box(k32.add_forces(&material, None, &pos32, &vel32, &mut f32s));
            }
            best[p][1] = best[p][1].min(t.elapsed().as_secs_f64() / EVALS as f64);
        }
    }
    force_path(VectorPath::Best);
    println!("| vector path | f64 µs | f64 ns/spring | f32 µs | f32 ns/spring | f64 / f32 |");
    println!("|---|---:|---:|---:|---:|---:|");
    for ((_, path), [t64, t32]) in paths.iter().zip(&best) {
        force_path(*path);
        let isa = active_isa_name();
        force_path(VectorPath::Best);
        println!(
            "| {isa} | {:.1} | {:.2} | {:.1} | {:.2} | {:.2} |",
            t64 * 1e6,
            t64 * 1e9 / springs as f64,
            t32 * 1e6,
            t32 * 1e9 / springs as f64,
            t64 / t32
        );
    }
}
