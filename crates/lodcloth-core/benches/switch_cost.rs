//! What a first switch to an unprepared level costs, phase by phase, on one
//! level of a shipped scene prepared as the daemon prepares it (issue 21:
//! the first switch after a cold start must answer in ≤ 10 s): the
//! reference recording, the level's dt, one coarse run over the whole
//! reference, each cheap estimate with its score, and the fit (with its
//! iterations and simulations). Everything f64, single process, the rayon
//! pool on every core, as in the daemon.
//!
//! `cargo bench -p lodcloth-core --bench switch_cost -- [--scene config/scenes/paper-3-left-edge.toml]
//! [--level 40x40] [--fit-frames 40] [--fit-iterations 6]`

use std::sync::Arc;
use std::time::Instant;

use lodcloth_core::estimate::{no_progress, Details, FitOptions, Method, RecordSpec};
use lodcloth_core::plan::{default_problem, record_reference};
use lodcloth_core::scene::Scene;

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let path = arg("--scene").unwrap_or_else(|| "../../config/scenes/paper-3-left-edge.toml".into());
    let level = arg("--level").unwrap_or_else(|| "40x40".into());
    let (nx, ny) = level
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
        .expect("--level NXxNY");
    let fit_frames: usize = arg("--fit-frames").map_or(40, |v| v.parse().expect("--fit-frames"));
    let fit_iterations: usize = arg("--fit-iterations").map_or(6, |v| v.parse().expect("--fit-iterations"));
    let scene = Scene::load(std::path::Path::new(&path)).expect("scene");
    // The daemon's default record spec ([estimation] in config/default.toml).
    let spec = RecordSpec {
        frames: 15_000,
        metric_stride: 40,
        estimate_stride: 40,
        difference_span: 1,
    };
    println!(
        "{} at {nx}x{ny}, reference {}x{} {} dt {:e}, {} threads",
        scene.name,
        scene.nx,
        scene.ny,
        scene.params.integrator.name(),
        scene.params.dt,
        rayon::current_num_threads()
    );

    let t = Instant::now();
    let (reference, _) = record_reference(&scene, spec, &mut |_| {}).expect("reference");
    println!("reference recording            {:7.2} s", t.elapsed().as_secs_f64());

    let t = Instant::now();
    let problem = default_problem(&scene, &reference, (nx, ny)).expect("level");
    let frames = problem.frames();
    println!(
        "level dt and problem           {:7.2} s  (dt {:e}, {frames} frames)",
        t.elapsed().as_secs_f64(),
        problem.dt,
    );

    let same = problem.same_material();
    let t = Instant::now();
    let report = problem.score(same, 0..frames, &mut no_progress).expect("score");
    let run = t.elapsed().as_secs_f64();
    println!(
        "one coarse run (score same)    {:7.2} s  (eq. 9 {:.3} %)",
        run,
        100.0 * report.mean
    );

    let fit = FitOptions {
        train: Some(0..frames),
        max_frames: fit_frames.min(frames),
        max_iterations: fit_iterations,
        ..FitOptions::default()
    };
    for method in [Method::Gkd, Method::Bcd, Method::Lsq] {
        let t = Instant::now();
        let est = problem.estimate(method, &fit, &mut no_progress).expect("estimate");
        let estimate = t.elapsed().as_secs_f64();
        let score = problem.score(est.material, 0..frames, &mut no_progress).expect("score");
        println!(
            "{:<5} estimate                 {:7.2} s  (eq. 9 {:.3} %{})",
            method.to_string(),
            estimate,
            100.0 * score.mean,
            if score.diverged { ", diverged" } else { "" }
        );
    }

    let t = Instant::now();
    let est = problem.estimate(Method::Fit, &fit, &mut no_progress).expect("fit");
    let seconds = t.elapsed().as_secs_f64();
    let score = problem.score(est.material, 0..frames, &mut no_progress).expect("score");
    if let Details::Fit(r) = &est.details {
        println!(
            "fit                            {:7.2} s  (eq. 9 {:.3} %; start {} {:.3} %, {} iterations, {} runs = {:.1} run-times, stop: {}{})",
            seconds,
            100.0 * score.mean,
            r.start,
            100.0 * r.start_rms,
            r.iterations,
            r.evaluations,
            seconds / run,
            r.stop,
            r.kept_start.as_ref().map_or(String::new(), |k| format!("; {k}"))
        );
    }
    let _ = Arc::strong_count(&reference);
}
