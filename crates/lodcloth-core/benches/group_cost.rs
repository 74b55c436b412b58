//! Cost per spring of each stencil group of a 64×64 cloth, alone: a symplectic
//! step with only that group (plus the fixed per-node work, measured with no
//! springs and subtracted). Diagnoses which spring direction is slow.
//!
//! `--path avx2` times the AVX2+FMA path on a CPU with AVX-512 (what an
//! AVX2-only CPU runs), `--path baseline` the target's baseline.
//!
//! `cargo bench -p lodcloth-core --bench group_cost -- [--path avx2|baseline]`
use std::sync::Arc;
use std::time::Instant;

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{active_isa_name, force_path, Loads, Simulation, StabilityCheck, State, Topology, VectorPath};

fn time_steps(topology: Topology, scene: &Scene) -> f64 {
    let topology = Arc::new(topology);
    let masses = scene.masses(&topology);
    let mut params = scene.params;
    params.strain_limit = None;
    params.stiffness_adjustment = None;
    let mut sim = Simulation::new(
        topology.clone(),
        masses,
        params,
        Loads::default(),
        State::at_rest(&topology),
        StabilityCheck::Force,
    )
    .expect("builds");
    for _ in 0..200 {
        sim.step();
    }
    let mut best = f64::INFINITY;
    for _ in 0..7 {
        let t = Instant::now();
        for _ in 0..2000 {
            sim.step();
        }
        best = best.min(t.elapsed().as_secs_f64() / 2000.0);
    }
    best
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    match args
        .iter()
        .position(|a| a == "--path")
        .and_then(|i| args.get(i + 1))
        .map(String::as_str)
    {
        None | Some("best") => {}
        Some("avx2") => {
            force_path(VectorPath::Avx2);
        }
        Some("baseline") => {
            force_path(VectorPath::Baseline);
        }
        Some(other) => panic!("--path {other}: expected best, avx2 or baseline"),
    }
    println!("vector path: {}", active_isa_name());
    let scene = Scene::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/scenes/hanging.toml"
    )))
    .expect("scene");
    let sim = scene.build().expect("builds");
    let full = (**sim.topology()).clone();
    let mut empty = full.clone();
    empty.groups.clear();
    let base = time_steps(empty, &scene);
    println!("no springs: {:.1} µs/step", base * 1e6);
    for (i, g) in full.groups.iter().enumerate() {
        let mut t = full.clone();
        t.groups = vec![g.clone()];
        let cost = time_steps(t, &scene) - base;
        println!(
            "group {i} {:<10} offset {:?}: {:5} springs, {:.1} µs, {:.2} ns/spring",
            g.class.name(),
            g.stencil_offset,
            g.len(),
            cost * 1e6,
            cost * 1e9 / g.len() as f64
        );
    }
    let all = time_steps(full.clone(), &scene) - base;
    println!(
        "all: {:.1} µs, {:.2} ns/spring",
        all * 1e6,
        all * 1e9 / full.spring_count() as f64
    );
}
