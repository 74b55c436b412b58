//! lodcloth's side of the peer comparison (`bench/peers/run.sh` runs it
//! before the peers and prints the ratio): the 64×64 step of the step
//! benchmark (the hanging scene's fabric, plain model: K 400/60/8 and C =
//! 1e-4 s × K, as `bench/peers/cloth_spec.py`), one thread, timed the way
//! the peers are: 50 warm-up steps, then `--repeats` runs of `--steps`
//! steps, median and fastest (7 runs by default, not the peers' 3: at
//! 0.06–0.24 s a run, one disturbed run moved a median of 3 by 15 %). dt is half the predicted limit (the step's
//! cost does not depend on it). Prints one line per integrator and, with
//! `--json PATH`, writes the figures for `cloth_peers.py --lodcloth PATH`.
//!
//! `cargo bench -p lodcloth-core --bench peer_step -- [--steps 1000] [--repeats 7] [--json PATH]`

use std::time::Instant;

use lodcloth_core::scene::Scene;
use lodcloth_core::sim::{active_isa_name, Integrator, StabilityCheck};

const SCENE: &str = include_str!("../../../config/scenes/hanging.toml");

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let steps: usize = arg("--steps").map_or(1000, |s| s.parse().expect("--steps: a count"));
    let repeats: usize = arg("--repeats").map_or(7, |s| s.parse().expect("--repeats: a count"));
    let mut entries = Vec::new();
    for integrator in [Integrator::SymplecticEuler, Integrator::Rk4] {
        let mut scene = Scene::from_toml(SCENE, "hanging.toml").expect("shipped scene is valid");
        scene.stability = StabilityCheck::Force;
        scene.params.integrator = integrator;
        scene.params.strain_limit = None;
        scene.params.stiffness_adjustment = None;
        scene.params.dt = 0.5 * scene.build_at(64, 64).expect("builds").dt_limit();
        let mut sim = scene.build_at(64, 64).expect("builds");
        let start = sim.clone();
        for _ in 0..50 {
            sim.step();
        }
        let mut times = Vec::new();
        for _ in 0..repeats {
            sim.clone_from(&start);
            let t = Instant::now();
            for _ in 0..steps {
                std::hint::black_box(sim.step());
            }
            times.push(t.elapsed().as_secs_f64() * 1e6 / steps as f64);
        }
        assert!(!sim.diverged(), "{integrator} diverged");
        times.sort_by(f64::total_cmp);
        let (median, min) = (times[times.len() / 2], times[0]);
        println!(
            "  lodcloth {:<17} f64 ({}): {median:9.1} us/step (min {min:.1}), {} springs",
            integrator.name(),
            active_isa_name(),
            sim.topology().spring_count()
        );
        entries.push(format!(
            "\"{integrator}\": {{\"us_per_step\": {median}, \"us_min\": {min}, \"isa\": \"{}\"}}",
            active_isa_name()
        ));
    }
    if let Some(path) = arg("--json") {
        std::fs::write(&path, format!("{{{}}}\n", entries.join(", "))).expect("--json: a writable path");
    }
}
