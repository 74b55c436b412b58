//! Cost of one step for square cloths of 16² … 256² nodes and every
//! integrator, on the hanging scene's fabric. Criterion reports time per step
//! and, as throughput, spring evaluations per second (springs × force
//! evaluations per step).
//!
//! dt is set per size and integrator to half its predicted stability limit
//! (explicit Euler: a quarter)
//! (implicit Euler: half the symplectic limit, which keeps its CG iteration
//! count realistic), so every run stays finite: a diverged run would time
//! NaN arithmetic or no-op steps.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{Integrator, StabilityCheck};

const SCENE: &str = include_str!("../../../config/scenes/hanging.toml");

fn bench_step(c: &mut Criterion) {
    let base = Scene::from_toml(SCENE, "hanging.toml").expect("shipped scene is valid");
    let sizes: Vec<usize> = std::env::var("LODCLOTH_BENCH_SIZES")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![16, 32, 64, 128, 256]);
    for integrator in Integrator::ALL {
        let mut group = c.benchmark_group(format!("step/{integrator}"));
        for &n in &sizes {
            let mut scene = base.clone();
            scene.stability = StabilityCheck::Force;
            scene.params.integrator = integrator;
            // The plain model, as the peers in bench/peers run it; the
            // strain-limited scene has its own group below.
            scene.params.strain_limit = None;
            scene.params.stiffness_adjustment = None;
            let probe = scene.build_at(n, n).expect("builds");
            let limit = match probe.dt_limit() {
                l if l.is_finite() => l,
                _ => probe.modal().dt_limit(Integrator::SymplecticEuler),
            };
            // Explicit Euler is stable only through damping and drifts
            // towards its limit as the cloth stretches: a quarter of it.
            let fraction = if integrator == Integrator::ExplicitEuler {
                0.25
            } else {
                0.5
            };
            scene.params.dt = fraction * limit;
            let mut sim = scene.build_at(n, n).expect("builds");
            // Let it fall for a moment so springs are stretched and moving.
            for _ in 0..20 {
                sim.step();
            }
            let springs = sim.topology().spring_count() as u64;
            group.throughput(Throughput::Elements(
                springs * u64::from(integrator.force_evaluations()),
            ));
            group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
                b.iter(|| sim.step());
            });
            // A diverged run times no-op steps: refuse to report it.
            assert!(!sim.diverged(), "{integrator} at {n}² diverged during the benchmark");
        }
        group.finish();
    }
    // The shipped hanging scene as it runs (strain limiting on), 64×64.
    let mut group = c.benchmark_group("step-strain-limited/symplectic_euler");
    let mut sim = base.build().expect("builds");
    for _ in 0..20 {
        sim.step();
    }
    group.throughput(Throughput::Elements(sim.topology().spring_count() as u64));
    group.bench_function(BenchmarkId::from_parameter(base.nx), |b| b.iter(|| sim.step()));
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).warm_up_time(std::time::Duration::from_millis(500)).measurement_time(std::time::Duration::from_secs(2));
    targets = bench_step
}
criterion_main!(benches);
