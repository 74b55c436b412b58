//! Time per step of the shipped hanging scene (64×64, strain-limited), from
//! rest over its first 3000 steps (fall, swing, limiter active most of the
//! time). The machine is shared and noisy, so the run is repeated and the
//! minimum and median are reported, of wall time and of the thread's own CPU
//! time (Linux `/proc/thread-self/schedstat`; it excludes time the thread was
//! preempted by other processes, so it is the steadier number there).
//!
//! `cargo bench -p lodcloth-core --bench profile_step -- [integrator] [trials]`
//! (integrator: symplectic_euler (default), explicit_euler, rk4, implicit_euler).

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::Integrator;

fn main() {
    let mut args = std::env::args().skip(1).filter(|a| a != "--bench");
    let integrator = args
        .next()
        .map(|s| Integrator::from_name(&s).expect("unknown integrator"))
        .unwrap_or(Integrator::SymplecticEuler);
    let trials: usize = args.next().map_or(5, |s| s.parse().expect("trials"));
    let mut scene = Scene::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/scenes/hanging.toml"
    )))
    .unwrap();
    scene.params.integrator = integrator;
    let n = 3000;
    let mut times = Vec::with_capacity(trials);
    let mut cpu_times = Vec::with_capacity(trials);
    let mut last = None;
    for _ in 0..trials {
        let mut sim = scene.build().unwrap();
        let cpu = cpu_ns();
        let t = std::time::Instant::now();
        for _ in 0..n {
            sim.step();
        }
        times.push(t.elapsed().as_secs_f64() * 1e6 / n as f64);
        if let (Some(a), Some(b)) = (cpu, cpu_ns()) {
            cpu_times.push((b - a) as f64 * 1e-3 / n as f64);
        }
        last = sim.last_report().copied();
    }
    println!("{integrator}: wall {}", summary(&times));
    if !cpu_times.is_empty() {
        println!("{integrator}: cpu  {}", summary(&cpu_times));
    }
    println!("last report {last:?}");
}

/// "min, median of n (all)" in µs/step.
fn summary(times: &[f64]) -> String {
    let mut sorted = times.to_vec();
    sorted.sort_by(f64::total_cmp);
    format!(
        "{:.1} us/step min, {:.1} median of {} ({})",
        sorted[0],
        sorted[sorted.len() / 2],
        times.len(),
        times.iter().map(|t| format!("{t:.1}")).collect::<Vec<_>>().join(" ")
    )
}

/// CPU time of this thread in ns, when the OS tells.
fn cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}
