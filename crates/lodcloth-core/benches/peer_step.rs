//! lodcloth's side of the peer comparison (`bench/peers/run.sh` runs it
//! before the peers and prints the ratio): the 64×64 step of the step
//! benchmark (the hanging scene's fabric, plain model: K 400/60/8 and C =
//! 1e-4 s × K, as `bench/peers/cloth_spec.py`), one thread, timed the way
//! the peers are: 50 warm-up steps, then `--repeats` runs of `--steps`
//! steps, median and fastest (7 runs by default, not the peers' 3: at
//! 0.06–0.24 s a run, one disturbed run moved a median of 3 by 15 %). dt is half the predicted limit (the step's
//! cost does not depend on it). Each integrator twice: springs in f64 and
//! in f32 (`SpringPrecision::F32`, the rest of the step in f64). Prints one
//! line per run and, with `--json PATH`, writes the figures for
//! `cloth_peers.py --lodcloth PATH`. `--path avx2` times the AVX2+FMA path
//! on a CPU with AVX-512 (what AVX2-only CPUs run).
//!
//! `--size N` times an N×N cloth instead of 64×64 (how the step's cost
//! per node grows once its fields leave the caches); the peers run 64×64
//! only.
//!
//! `--only KEY` times one entry (`symplectic_euler`, `symplectic_euler_f32`,
//! `rk4`, `rk4_f32`), e.g. under a profiler.
//!
//! The step is `Simulation::step_lean` (since 2026-12-02): a peer's step
//! computes forces and integrates, and reports no energies; the lean step
//! leaves out the springs' energy and largest strain too (it still sums the
//! kinetic and gravity energy and checks every value is finite).
//! `--report full` times `Simulation::step`, with every figure of the
//! report (what the figures before that date were).
//!
//! `cargo bench -p lodcloth-core --bench peer_step -- [--steps 1000] [--repeats 7] [--json PATH] [--path avx2] [--only KEY] [--report lean|full] [--size N]`

use std::time::Instant;

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{active_isa_name, force_path, Integrator, SpringPrecision, StabilityCheck, VectorPath};

const SCENE: &str = include_str!("../../../config/scenes/hanging.toml");

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let steps: usize = arg("--steps").map_or(1000, |s| s.parse().expect("--steps: a count"));
    match arg("--path").as_deref() {
        None | Some("best") => {}
        Some("avx2") => {
            force_path(VectorPath::Avx2);
        }
        Some(other) => panic!("--path {other}: expected best or avx2"),
    }
    let repeats: usize = arg("--repeats").map_or(7, |s| s.parse().expect("--repeats: a count"));
    let only = arg("--only");
    let size: usize = arg("--size").map_or(64, |s| s.parse().expect("--size: nodes a side"));
    assert!(
        size == 64 || arg("--json").is_none(),
        "--json writes the figures the peers' 64×64 are compared with: leave out --size {size}"
    );
    let full = match arg("--report").as_deref() {
        None | Some("lean") => false,
        Some("full") => true,
        Some(other) => panic!("--report {other}: expected lean or full"),
    };
    let step = |sim: &mut lodcloth_core::sim::Simulation| if full { sim.step() } else { sim.step_lean() };
    let mut entries = Vec::new();
    for (integrator, precision) in [Integrator::SymplecticEuler, Integrator::Rk4]
        .into_iter()
        .flat_map(|i| SpringPrecision::ALL.map(|p| (i, p)))
    {
        let key = match precision {
            SpringPrecision::F64 => integrator.name().to_string(),
            SpringPrecision::F32 => format!("{integrator}_f32"),
        };
        if only.as_ref().is_some_and(|o| *o != key) {
            continue;
        }
        let mut scene = Scene::from_toml(SCENE, "hanging.toml").expect("shipped scene is valid");
        scene.stability = StabilityCheck::Force;
        scene.params.integrator = integrator;
        scene.params.strain_limit = None;
        scene.params.stiffness_adjustment = None;
        scene.params.dt = 0.5 * scene.build_at(size, size).expect("builds").dt_limit();
        let mut sim = scene.build_at(size, size).expect("builds");
        sim.set_spring_precision(precision);
        let start = sim.clone();
        for _ in 0..50 {
            sim.step();
        }
        let mut times = Vec::new();
        for _ in 0..repeats {
            sim.clone_from(&start);
            let t = Instant::now();
            for _ in 0..steps {
                std::hint::black_box(step(&mut sim));
            }
            times.push(t.elapsed().as_secs_f64() * 1e6 / steps as f64);
        }
        assert!(!sim.diverged(), "{integrator} diverged");
        times.sort_by(f64::total_cmp);
        let (median, min) = (times[times.len() / 2], times[0]);
        let springs = match precision {
            SpringPrecision::F64 => "f64",
            SpringPrecision::F32 => "f32 springs",
        };
        println!(
            "  lodcloth {:<17} {springs:<11} ({}, {} report): {median:9.1} us/step (min {min:.1}), {size}×{size}, {} springs, {:.2} ns/spring",
            integrator.name(),
            active_isa_name(),
            if full { "full" } else { "lean" },
            sim.topology().spring_count(),
            median * 1e3 / sim.topology().spring_count() as f64
        );
        entries.push(format!(
            "\"{key}\": {{\"us_per_step\": {median}, \"us_min\": {min}, \"isa\": \"{}\", \"report\": \"{}\"}}",
            active_isa_name(),
            if full { "full" } else { "lean" }
        ));
    }
    if let Some(path) = arg("--json") {
        std::fs::write(&path, format!("{{{}}}\n", entries.join(", "))).expect("--json: a writable path");
    }
}
