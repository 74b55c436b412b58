//! A large cloth's step on one thread and on two (issue 21: 256×256 on two
//! threads at least 1.8× one thread). The step of a cloth of at least
//! `SPLIT_MIN_NODES` nodes is split in two fixed halves; here it runs them
//! once on one thread (`Serial`) and once with a second thread lent through
//! a `Lender` (a helper that does nothing else, as the daemon's partner
//! stepping thread does when idle). Both runs are interleaved batch by
//! batch in one process and the states checked bit-identical at the end.
//! Prints µs per step, the speed-up and the spring throughput.
//!
//! `cargo bench -p lodcloth-core --bench two_threads -- [--sizes 128,256] [--batches 9] [--precision f32]`
//! (`--precision f32`: springs in f32, `SpringPrecision::F32`).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{
    active_isa_name, Integrator, Lender, Pair, Serial, Simulation, SpringPrecision, StabilityCheck,
};

/// How long a helper waits for the next half before parking (the daemon's
/// value).
const LINGER: std::time::Duration = std::time::Duration::from_micros(200);

const SCENE: &str = include_str!("../../../config/scenes/hanging.toml");

fn sim(integrator: Integrator, n: usize) -> Simulation {
    let mut scene = Scene::from_toml(SCENE, "hanging.toml").expect("shipped scene is valid");
    scene.stability = StabilityCheck::Force;
    scene.params.integrator = integrator;
    scene.params.strain_limit = None;
    scene.params.stiffness_adjustment = None;
    let limit = scene.build_at(n, n).expect("builds").dt_limit();
    scene.params.dt = 0.5 * limit;
    let mut sim = scene.build_at(n, n).expect("builds");
    sim.set_spring_precision(arg("--precision").map_or(SpringPrecision::F64, |p| {
        SpringPrecision::from_name(&p).expect("--precision: f64 or f32")
    }));
    for _ in 0..20 {
        sim.step();
    }
    sim
}

/// µs per step over `steps` steps on `pair`.
fn time(sim: &mut Simulation, pair: &dyn Pair, steps: usize) -> f64 {
    let t = Instant::now();
    for _ in 0..steps {
        std::hint::black_box(sim.step_on(pair));
    }
    t.elapsed().as_secs_f64() * 1e6 / steps as f64
}

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let sizes: Vec<usize> = arg("--sizes")
        .map(|s| {
            s.split(',')
                .map(|x| x.trim().parse().expect("--sizes: a list of sizes"))
                .collect()
        })
        .unwrap_or_else(|| vec![128, 256]);
    let batches: usize = arg("--batches").map_or(9, |b| b.parse().expect("--batches: a count"));
    let lender = Arc::new(Lender::new());
    let stop = Arc::new(AtomicBool::new(false));
    let helper = {
        let (lender, stop) = (lender.clone(), stop.clone());
        std::thread::spawn(move || {
            lender.set_helper(std::thread::current());
            while !stop.load(Ordering::Relaxed) {
                // As the daemon's stepping threads serve each other.
                if lender.help_lingering(LINGER, Instant::now() + LINGER) == 0 {
                    std::thread::park_timeout(std::time::Duration::from_millis(1));
                }
            }
        })
    };
    println!(
        "two threads against one, {} path, {} cores; fastest of {batches} interleaved batches",
        active_isa_name(),
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    println!("| size | integrator | one thread µs/step | two threads µs/step | speed-up | ns per spring evaluation (two threads) |");
    println!("|---|---|---|---|---|---|");
    for integrator in [Integrator::SymplecticEuler, Integrator::Rk4] {
        for &n in &sizes {
            let mut one = sim(integrator, n);
            let mut two = one.clone();
            if one.split().is_none() {
                println!("| {n}×{n} | {integrator} | — | — | does not split | — |");
                continue;
            }
            // About 50 ms per batch.
            let steps = (50_000.0 / time(&mut one.clone(), &Serial, 3)).ceil().max(3.0) as usize;
            let (mut best1, mut best2) = (f64::INFINITY, f64::INFINITY);
            for _ in 0..batches {
                best1 = best1.min(time(&mut one, &Serial, steps));
                best2 = best2.min(time(&mut two, &*lender, steps));
            }
            let same = one
                .state()
                .pos
                .iter()
                .zip(&two.state().pos)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "{integrator} {n}: one and two threads differ");
            let evals = one.topology().spring_count() as f64 * f64::from(integrator.force_evaluations());
            println!(
                "| {n}×{n} | {integrator} | {best1:.1} | {best2:.1} | {:.2}× | {:.2} |",
                best1 / best2,
                best2 * 1e3 / evals
            );
        }
    }
    stop.store(true, Ordering::Relaxed);
    helper.thread().unpark();
    helper.join().expect("helper");
}
