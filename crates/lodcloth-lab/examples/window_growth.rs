//! How a level's short-horizon error builds up within a window: the level
//! restarted from the reference every w (the short horizon restarts every
//! 0.25 s) and scored on the held-out half, for w from one metric frame
//! up. The mean over windows of length w is the error averaged over the
//! first w after a restart, so the shortest window reads what a restart
//! itself leaves (the transfer and its settling, one frame of motion) and
//! the longer ones how fast the level then leaves the reference.
//!
//! ```text
//! cargo run --release -p lodcloth-lab --example window_growth -- SCENE --level 40% [--frames 20000] [--method same] [--settle 0.0167]
//! ```
//! Trained (for an estimator) on the first half, as `experiment
//! generalise` does; `same` needs no training. Measured with it:
//! NOTEBOOK.md, "What the short horizon is made of".
use std::path::PathBuf;
use std::time::Instant;

use lodcloth::estimate::{no_progress, FitOptions, Method, RecordSpec};
use lodcloth::level::GridLevel;
use lodcloth::plan::{default_problem, record_reference, stable_problem};
use lodcloth::scene::Scene;

#[derive(clap::Parser)]
struct Args {
    /// A scene file.
    scene: PathBuf,
    /// The level (a grid's N or NXxNY, a mesh's P% or Nv).
    #[arg(long)]
    level: GridLevel,
    /// Reference steps.
    #[arg(long, default_value_t = 20_000)]
    frames: u64,
    /// The estimator.
    #[arg(long, default_value = "same")]
    method: String,
    /// Settle every restart by one backward-Euler step of this many
    /// seconds (`lodcloth_core::lod::settle`).
    #[arg(long)]
    settle: Option<f64>,
    /// Window lengths (s); each is rounded to whole metric frames.
    #[arg(long, value_delimiter = ',', default_value = "0,0.005,0.01,0.025,0.05,0.1,0.25")]
    windows: Vec<f64>,
}

fn main() {
    let args = <Args as clap::Parser>::parse();
    let scene = Scene::load(&args.scene).unwrap_or_else(|e| panic!("{}: {e}", args.scene.display()));
    let method = Method::from_name(&args.method).unwrap_or_else(|| panic!("unknown method {:?}", args.method));
    let spec = RecordSpec {
        frames: args.frames,
        metric_stride: 10,
        estimate_stride: 40,
        difference_span: 1,
    };
    let t = Instant::now();
    let (reference, _) =
        record_reference(&scene, spec, &mut |line| eprintln!("{line}")).expect("the reference records");
    eprintln!("reference recorded in {:.1} s", t.elapsed().as_secs_f64());
    let vertices = scene.mesh.as_ref().map(|m| m.reference.vertices());
    let level = args
        .level
        .on(scene.width, scene.height, vertices)
        .unwrap_or_else(|e| panic!("{}: {e}", args.level));
    let mut problem = default_problem(&scene, &reference, level).expect("the level builds");
    if let Some(h) = args.settle {
        problem = problem.with_settling(h);
    }
    let frames = problem.frames();
    let train_end = frames / 2;
    let fit = FitOptions {
        train: Some(0..train_end),
        ..FitOptions::default()
    };
    let material = problem
        .estimate(method, &fit, &mut no_progress)
        .expect("the estimate")
        .material;
    let (problem, _) = stable_problem(&problem, material).expect("a stable dt");
    let interval = reference.dt * reference.spec.metric_stride as f64;
    println!(
        "{} {level} {method}{}: the short horizon's mean over the held-out half, restarted every w (O_max {:.4} m, metric frame {:.1} ms)",
        scene.name,
        args.settle.map_or(String::new(), |h| format!(", settled {h} s")),
        reference.o_max,
        1e3 * interval
    );
    println!("| w (s) | frames | mean % | p95 % |\n|---|---|---|---|");
    for w in &args.windows {
        let window = ((w / interval).round() as usize).max(1);
        let report = problem
            .score_windows(material, train_end..frames, window, &mut no_progress)
            .expect("scores");
        println!(
            "| {:.3} | {window} | {:.2} | {:.2} |",
            window as f64 * interval,
            100.0 * report.mean,
            100.0 * report.p95
        );
    }
}
