//! The vectorisation guard (CI, issue 21): the 64×64 step of the step
//! benchmark (the hanging scene's fabric, strain control off), symplectic
//! Euler and RK4, timed on this CPU's best vector path and on the target's
//! baseline (x86-64: SSE2) in one run, interleaved. Prints both and their
//! ratio; exits 1 when the best path is not at least `--min-ratio` (default
//! 3) times faster, which is what happens when a function on the hot path
//! stops being inlined into the dispatched closure and silently runs
//! baseline code (the outputs stay bit-identical, so no test sees it). On
//! a CPU without AVX2 the guard says so and passes.
//!
//! Measured (2 cores, AMD EPYC family 25 model 17, AVX-512, 2026-11-25):
//! 8.4× for both integrators (the baseline has no hardware FMA, so its
//! `mul_add` is a library call); with only the horizontal springs' kernel
//! (`run_carry`) made `#[inline(never)]`, 2.4×.
//!
//! `cargo bench -p lodcloth-core --bench vector_guard -- [--min-ratio 3]`

use std::time::Instant;

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{active_isa_name, force_path, Integrator, Simulation, StabilityCheck, VectorPath};

const SCENE: &str = include_str!("../../../config/scenes/hanging.toml");
/// Steps per timed batch, and batches per path (the fastest batch counts:
/// the other core of a 2-core machine only ever slows a batch down).
const STEPS: [(Integrator, usize); 2] = [(Integrator::SymplecticEuler, 400), (Integrator::Rk4, 100)];
const BATCHES: usize = 15;

fn sim(integrator: Integrator) -> Simulation {
    let mut scene = Scene::from_toml(SCENE, "hanging.toml").expect("shipped scene is valid");
    scene.stability = StabilityCheck::Force;
    scene.params.integrator = integrator;
    scene.params.strain_limit = None;
    scene.params.stiffness_adjustment = None;
    let limit = scene.build_at(64, 64).expect("builds").dt_limit();
    scene.params.dt = 0.5 * limit;
    let mut sim = scene.build_at(64, 64).expect("builds");
    for _ in 0..20 {
        sim.step();
    }
    sim
}

/// Fastest time per step (µs) over `BATCHES` batches of `steps`.
fn time(sim: &mut Simulation, steps: usize) -> f64 {
    let t = Instant::now();
    for _ in 0..steps {
        std::hint::black_box(sim.step());
    }
    t.elapsed().as_secs_f64() * 1e6 / steps as f64
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let min_ratio: f64 = args
        .iter()
        .position(|a| a == "--min-ratio")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(3.0);
    let best = active_isa_name();
    println!("vector guard: 64x64 step, best path {best} against the baseline, fastest of {BATCHES} batches");
    if best == "baseline" {
        println!("vector guard: this CPU has no vector path beyond the baseline; nothing to guard");
        return;
    }
    let mut failed = Vec::new();
    for (integrator, steps) in STEPS {
        // One cloth per path, stepped in alternation, so both see the same
        // machine at the same time.
        let mut fast = sim(integrator);
        let mut slow = sim(integrator);
        let (mut t_best, mut t_base) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..BATCHES {
            force_path(VectorPath::Best);
            t_best = t_best.min(time(&mut fast, steps));
            force_path(VectorPath::Baseline);
            t_base = t_base.min(time(&mut slow, steps));
        }
        force_path(VectorPath::Best);
        assert!(!fast.diverged() && !slow.diverged(), "{integrator} diverged");
        let ratio = t_base / t_best;
        println!(
            "vector guard: {integrator:<17} {best} {t_best:8.1} µs/step, baseline {t_base:8.1} µs/step, ratio {ratio:.2} (at least {min_ratio})"
        );
        if ratio < min_ratio {
            failed.push(format!("{integrator}: {ratio:.2}"));
        }
    }
    if !failed.is_empty() {
        eprintln!(
            "vector guard FAILED: the {best} path is not {min_ratio}x the baseline ({}); a function on the \
             step's hot path probably lost #[inline(always)] and runs baseline code (see sim/simd.rs)",
            failed.join(", ")
        );
        std::process::exit(1);
    }
}
