//! Time per step of the shipped hanging scene (64×64, strain-limited), from
//! rest over its first 3000 steps (fall, swing, limiter active most of the
//! time). The machine is shared and noisy, so the run is repeated and the
//! minimum and median are reported.
//!
//! `cargo run --release --example profile_step -- [integrator] [trials]`
//! (integrator: symplectic_euler (default), explicit_euler, rk4, implicit_euler).

use lodcloth::scene::Scene;
use lodcloth::sim::Integrator;

fn main() {
    let mut args = std::env::args().skip(1);
    let integrator = args
        .next()
        .map(|s| Integrator::from_name(&s).expect("unknown integrator"))
        .unwrap_or(Integrator::SymplecticEuler);
    let trials: usize = args.next().map_or(5, |s| s.parse().expect("trials"));
    let mut scene = Scene::load(std::path::Path::new("config/scenes/hanging.toml")).unwrap();
    scene.params.integrator = integrator;
    let n = 3000;
    let mut times = Vec::with_capacity(trials);
    let mut last = None;
    for _ in 0..trials {
        let mut sim = scene.build().unwrap();
        let t = std::time::Instant::now();
        for _ in 0..n {
            sim.step();
        }
        times.push(t.elapsed().as_secs_f64() * 1e6 / n as f64);
        last = sim.last_report().copied();
    }
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "{integrator}: {:.1} us/step min, {:.1} median of {trials} ({}); report {last:?}",
        sorted[0],
        sorted[trials / 2],
        times.iter().map(|t| format!("{t:.1}")).collect::<Vec<_>>().join(" ")
    );
}
