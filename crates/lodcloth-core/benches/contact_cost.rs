//! What contact costs a step: the tablecloth-over-table scene at several
//! levels, settled on the table (most nodes pressed against it), stepped
//! with its collider and, from the same state, without it; and with the
//! table moved far away (every node rejected by the cheap bound). Prints
//! µs per step, the overhead and the ratio. Strain limiting is off in all
//! three, so the difference is contact's alone.
//!
//! `cargo bench -p lodcloth-core --bench contact_cost -- [--levels 24,48,64] [--integrator rk4|symplectic_euler]`
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{Collider, Integrator, Simulation, StabilityCheck, State};

fn arg<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(String::as_str)
}

/// Best µs per step over 5 runs of `steps`, each from `state`.
fn time(sim: &mut Simulation, state: &State, steps: usize) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        sim.set_state(state.clone()).expect("state fits");
        let t = Instant::now();
        for _ in 0..steps {
            sim.step();
        }
        best = best.min(t.elapsed().as_secs_f64() / steps as f64);
    }
    best * 1e6
}

fn with_colliders(sim: &Simulation, colliders: Vec<Collider>, state: &State) -> Simulation {
    let mut loads = sim.loads().clone();
    loads.colliders = colliders;
    let topology = Arc::clone(sim.topology());
    Simulation::new(
        topology,
        sim.masses().to_vec(),
        *sim.params(),
        loads,
        state.clone(),
        StabilityCheck::Force,
    )
    .expect("builds")
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let levels: Vec<usize> = arg(&args, "--levels")
        .unwrap_or("24,48,64")
        .split(',')
        .map(|s| s.parse().expect("--levels: node counts per side"))
        .collect();
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/scenes/tablecloth-over-table.toml"
    ));
    let mut scene = Scene::load(path).expect("scene");
    // Without strain limiting: its sweeps depend on the shape (a draped
    // cloth has more over-long springs than one falling free), which would
    // be counted as contact's.
    scene.params.strain_limit = None;
    if let Some(name) = arg(&args, "--integrator") {
        scene.params.integrator = match name {
            "rk4" => Integrator::Rk4,
            "symplectic_euler" => Integrator::SymplecticEuler,
            other => panic!("--integrator {other}: expected rk4 or symplectic_euler"),
        };
    }
    println!(
        "scene {} ({}, no strain limiting), dt {:e} s; settled 1.5 s on the table, then 400 steps timed, best of 5",
        scene.name,
        scene.params.integrator.name(),
        scene.params.dt
    );
    println!("| level | nodes | contacts | with table µs | without µs | overhead µs | ratio | table far away µs | ns per node, far |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for n in levels {
        let mut sim = scene.build_at(n, n).expect("builds");
        let settle = (1.5 / scene.params.dt).round() as usize;
        let mut contacts = 0;
        for _ in 0..settle {
            contacts = sim.step().contacts;
        }
        let state = sim.state().clone();
        let with = time(&mut sim, &state, 400);
        let mut bare = with_colliders(&sim, Vec::new(), &state);
        let without = time(&mut bare, &state, 400);
        let mut far_table = sim.loads().colliders.clone();
        for body in &mut far_table {
            body.position[1] -= 100.0;
        }
        let mut far = with_colliders(&sim, far_table, &state);
        let far_cost = time(&mut far, &state, 400);
        let nodes = sim.topology().n_nodes;
        println!(
            "| {n}×{n} | {nodes} | {contacts} | {with:.1} | {without:.1} | {:.1} | {:.3} | {far_cost:.1} | {:.2} |",
            with - without,
            with / without,
            (far_cost - without) * 1e3 / nodes as f64,
        );
    }
}
