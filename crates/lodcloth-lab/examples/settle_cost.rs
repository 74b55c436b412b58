//! What settling a switch down costs (`lodcloth_core::lod::settle`): a
//! mesh scene's finer level is stepped for a second, its state carried to
//! each coarser level, and the settling timed in its two parts, building
//! the twin (`lod::settler`, which the daemon does off the stepping thread)
//! and settling with it (`lod::settle_with`, on the stepping thread), best
//! of five, against one step of the coarser level.
//!
//! ```text
//! cargo run --release -p lodcloth-lab --example settle_cost -- [SCENE] [--from 1370v] [--to 915v,570v] [--settle 0.0167]
//! ```
//! Defaults: the skirt (`config/scenes/skirt-swaying.toml`) and the levels
//! and step of the default config's skirt instance. Measured with it:
//! NOTEBOOK.md, "Settling what a level cannot hold".
use std::path::PathBuf;
use std::time::Instant;

use lodcloth_core::level::GridLevel;
use lodcloth_core::lod::{settle_with, settler, transfer_state};
use lodcloth_core::scene::Scene;

#[derive(clap::Parser)]
struct Args {
    /// A mesh scene.
    #[arg(default_value = "config/scenes/skirt-swaying.toml")]
    scene: PathBuf,
    /// The level switched from.
    #[arg(long, default_value = "1370v")]
    from: GridLevel,
    /// The levels switched to.
    #[arg(long, value_delimiter = ',', default_value = "915v,570v")]
    to: Vec<GridLevel>,
    /// The settling step (s).
    #[arg(long, default_value_t = 1.0 / 60.0)]
    settle: f64,
}

/// The fastest of five runs of `f` (s).
fn best_of_five(mut f: impl FnMut()) -> f64 {
    (0..5)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let args = <Args as clap::Parser>::parse();
    let scene = Scene::load(&args.scene).unwrap_or_else(|e| panic!("{}: {e}", args.scene.display()));
    let vertices = scene.mesh.as_ref().map(|m| m.reference.vertices());
    let level = |l: GridLevel| {
        l.on(scene.width, scene.height, vertices)
            .unwrap_or_else(|e| panic!("{l}: {e}"))
    };
    let mut fine = scene.build_level(level(args.from)).expect("the finer level builds");
    while fine.state().time < 1.0 {
        assert!(fine.step().finite, "the finer level diverged");
    }
    for to in &args.to {
        let mut coarse = scene.build_level(level(*to)).expect("the coarser level builds");
        let carried = transfer_state(fine.topology(), fine.state(), coarse.topology()).expect("transfer");
        coarse.set_state(carried.clone()).expect("state");
        let build = best_of_five(|| drop(settler(&coarse, args.settle).expect("a twin")));
        let mut twin = settler(&coarse, args.settle).expect("a twin");
        let mut moved = None;
        let settling = best_of_five(|| {
            coarse.set_state(carried.clone()).expect("state");
            moved = Some(settle_with(&mut coarse, &mut twin).expect("settles"));
        });
        let iterations = twin.last_report().map_or(0, |r| r.solver_iterations);
        coarse.set_state(carried.clone()).expect("state");
        let steps = 100;
        let step = best_of_five(|| {
            for _ in 0..steps {
                coarse.step();
            }
        }) / steps as f64;
        let moved = moved.expect("settled");
        println!(
            "{} -> {to}: twin built in {:.2} ms, settled in {:.2} ms ({iterations} CG iterations; moved rms {:.3} mm, max {:.3} mm); one step {:.3} ms (dt {:e} s)",
            args.from,
            1e3 * build,
            1e3 * settling,
            1e3 * moved.rms,
            1e3 * moved.max,
            1e3 * step,
            coarse.params().dt
        );
    }
}
