//! The vectorisation guard (CI, issue 21): the 64×64 step of the step
//! benchmark (the hanging scene's fabric, strain control off), symplectic
//! Euler, RK4 and XPBD, timed on this CPU's best vector path and on the target's
//! baseline (x86-64: SSE2) in one run, interleaved. Prints both and their
//! ratio; exits 1 when the best path is not at least its floor times faster
//! (4.3 with f64 springs, 5.5 with f32 springs, 1.3 for XPBD; `--min-ratio`
//! sets the first two), which is what happens when a function on the hot path
//! stops being inlined into the dispatched closure and silently runs
//! baseline code (the outputs stay bit-identical, so no test sees it). On
//! a CPU without AVX2 the guard says so and passes. Both spring precisions
//! (`SpringPrecision::F64` and `F32`, the daemon's default cloths) are
//! guarded, each with its own vector path through the kernel.
//!
//! Measured (2 cores, AMD EPYC family 25 model 17, AVX-512, 2026-11-25):
//! 8.4× for both integrators (the baseline has no hardware FMA, so its
//! `mul_add` is a library call); with only the horizontal springs' kernel
//! (`run_carry`) made `#[inline(never)]`, 2.4×.
//!
//! It also guards the cache layout of the field buffers: a 64×64 cloth's
//! component arrays are 32 KiB long, so every array it streams through
//! maps to the same L1 sets unless the workspace places its buffers apart
//! (`sim/paged.rs`). The time per spring of 64×64 is compared with 62×62's
//! in the same run; it fails above `--max-layout-ratio` (default 1.3).
//! Measured on the machine above: 2.31 for symplectic Euler before the
//! buffers were placed (141 against 57 µs/step), 0.95 after (55 and 54).
//! The vector ratio is 15× since then (the baseline keeps its conflicts).
//!
//! The floors were 3 for both precisions until 2026-12-02, when a kernel
//! whose lane arithmetic was split into several loops (LLVM's SLP
//! vectoriser then makes partly scalar code) ran the f64 step 3.5× slower
//! on the AVX2 path and still passed: healthy ratios are 9–13 (f64) and
//! 19–31 (f32) on the machines measured (docs/results.md, "The
//! vectorisation guard"), so the floors now sit about half-way below the
//! lowest of them. On 2026-12-03 the kernel's Newton steps (a library call
//! for every `mul_add` on the baseline) gave way to a square root and a
//! division, which the baseline has in hardware: it became twice as fast,
//! and healthy ratios fell to 6.1–10.0 (f64) and 10.6–15.7 (f32) on the
//! Zen 4, both paths, while `run_carry` made `#[inline(never)]` read
//! 2.40–3.03 on all eight spring entries; the floors went from 5 and 8 to
//! 4.3 and 5.5, about the geometric middle of the two.
//!
//! `cargo bench -p lodcloth-core --bench vector_guard -- [--min-ratio 5] [--max-layout-ratio 1.3] [--path avx2]`

use std::time::Instant;

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{
    active_isa_name, force_path, Integrator, Simulation, SpringPrecision, StabilityCheck, VectorPath,
};

const SCENE: &str = include_str!("../../../config/scenes/hanging.toml");
/// Steps per timed batch, and batches per path (the fastest batch counts:
/// the other core of a 2-core machine only ever slows a batch down).
const STEPS: [(Integrator, usize); 3] = [
    (Integrator::SymplecticEuler, 400),
    (Integrator::Rk4, 100),
    (Integrator::Xpbd, 200),
];
const BATCHES: usize = 15;
/// XPBD's own floor for the vector ratio. Its sweep is bound by division and
/// square-root throughput, where the baseline's two lanes already do a
/// quarter of AVX-512's work: 2.0× measured (Zen 4, 2026-12-02: 147 against
/// 296 µs a step). A sweep fallen back to baseline code reads ~1.0; one
/// pass left out of the dispatch (the length pass, measured) 1.6.
const XPBD_MIN_RATIO: f64 = 1.3;
/// Floors of the vector ratio for the spring integrators, by spring
/// precision (see the module note): a healthy f64 step is 6–10× the
/// baseline, an f32 one 10–16× (f32 has twice the lanes, and the baseline
/// pays a library call for each `mul_add` in both).
const F64_MIN_RATIO: f64 = 4.3;
const F32_MIN_RATIO: f64 = 5.5;

/// Every (integrator, steps) with each spring precision; XPBD once (its
/// sweep is f64 whatever the precision).
fn cases() -> Vec<((Integrator, usize), SpringPrecision)> {
    STEPS
        .into_iter()
        .flat_map(|s| SpringPrecision::ALL.map(|p| (s, p)))
        .filter(|&((i, _), p)| i != Integrator::Xpbd || p == SpringPrecision::F64)
        .collect()
}

fn sim(integrator: Integrator, n: usize, precision: SpringPrecision) -> Simulation {
    let mut scene = Scene::from_toml(SCENE, "hanging.toml").expect("shipped scene is valid");
    scene.stability = StabilityCheck::Force;
    scene.params.integrator = integrator;
    scene.params.strain_limit = None;
    scene.params.stiffness_adjustment = None;
    let probe = scene.build_at(n, n).expect("builds");
    // XPBD has no limit: half the symplectic one, as for the others.
    let limit = match probe.dt_limit() {
        l if l.is_finite() => l,
        _ => probe.modal().dt_limit(Integrator::SymplecticEuler),
    };
    scene.params.dt = 0.5 * limit;
    let mut sim = scene.build_at(n, n).expect("builds");
    sim.set_spring_precision(precision);
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
    let min_ratio: Option<f64> = args
        .iter()
        .position(|a| a == "--min-ratio")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok());
    let max_layout: f64 = args
        .iter()
        .position(|a| a == "--max-layout-ratio")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(1.3);
    // `--path avx2`: guard the AVX2 path on a CPU that has AVX-512 too (what
    // an AVX2-only CPU runs).
    let path = if args.iter().any(|a| a == "avx2") {
        VectorPath::Avx2
    } else {
        VectorPath::Best
    };
    force_path(path);
    let best = active_isa_name();
    let mut failed = Vec::new();
    layout_guard(max_layout, &mut failed);
    println!("vector guard: 64x64 step, best path {best} against the baseline, fastest of {BATCHES} batches");
    if best == "baseline" {
        println!("vector guard: this CPU has no vector path beyond the baseline; nothing to guard");
        return finish(&failed, best);
    }
    for ((integrator, steps), precision) in cases() {
        // One cloth per path, stepped in alternation, so both see the same
        // machine at the same time.
        let mut fast = sim(integrator, 64, precision);
        let mut slow = sim(integrator, 64, precision);
        let (mut t_best, mut t_base) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..BATCHES {
            force_path(path);
            t_best = t_best.min(time(&mut fast, steps));
            force_path(VectorPath::Baseline);
            t_base = t_base.min(time(&mut slow, steps));
        }
        force_path(path);
        assert!(!fast.diverged() && !slow.diverged(), "{integrator} diverged");
        let ratio = t_base / t_best;
        let min_ratio = match (integrator, precision) {
            (Integrator::Xpbd, _) => XPBD_MIN_RATIO,
            (_, SpringPrecision::F64) => min_ratio.unwrap_or(F64_MIN_RATIO),
            (_, SpringPrecision::F32) => min_ratio.unwrap_or(F32_MIN_RATIO),
        };
        println!(
            "vector guard: {integrator:<17} {precision} springs {best} {t_best:8.1} µs/step, baseline {t_base:8.1} µs/step, ratio {ratio:.2} (at least {min_ratio})"
        );
        if ratio < min_ratio {
            failed.push(format!("{integrator} {precision}: {ratio:.2} < {min_ratio}"));
        }
    }
    finish(&failed, best);
}

fn finish(failed: &[String], best: &str) {
    if !failed.is_empty() {
        eprintln!(
            "vector guard FAILED ({}): a vector ratio below its floor means a function on the step's hot \
             path lost #[inline(always)] and runs baseline code on the {best} path (see sim/simd.rs); a layout \
             ratio above its bound means the field buffers compete for L1 sets again (see sim/paged.rs)",
            failed.join("; ")
        );
        std::process::exit(1);
    }
}

/// Time per spring of 64×64 against 62×62, best path, interleaved.
fn layout_guard(max_ratio: f64, failed: &mut Vec<String>) {
    println!(
        "layout guard: time per spring, 64x64 (32-KiB component arrays) against 62x62, fastest of {BATCHES} batches"
    );
    for ((integrator, steps), precision) in cases() {
        let mut pow2 = sim(integrator, 64, precision);
        let mut other = sim(integrator, 62, precision);
        let per_spring = |sim: &Simulation, t: f64| t * 1e3 / sim.topology().spring_count() as f64;
        let (mut t_pow2, mut t_other) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..BATCHES {
            t_pow2 = t_pow2.min(time(&mut pow2, steps));
            t_other = t_other.min(time(&mut other, steps));
        }
        assert!(!pow2.diverged() && !other.diverged(), "{integrator} diverged");
        let (a, b) = (per_spring(&pow2, t_pow2), per_spring(&other, t_other));
        let ratio = a / b;
        println!(
            "layout guard: {integrator:<17} {precision} springs 64x64 {a:6.2} ns/spring ({t_pow2:.1} µs/step), 62x62 {b:6.2} ns/spring ({t_other:.1} µs/step), ratio {ratio:.2} (at most {max_ratio})"
        );
        if ratio > max_ratio {
            failed.push(format!("layout {integrator} {precision}: {ratio:.2}"));
        }
    }
}
