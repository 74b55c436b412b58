//! Figures for point-sampled surfaces (README, issue 5): time per step with
//! the transfer and normals included, for 85, 273 and 327 simulation points
//! on the paper's 3,203-point sphere, side by side with Su et al.'s
//! Pentium IV figures; the same for a 100k-point sphere; and the cost of the
//! set-up stages (normals, simplification, springs, transfer weights).
//!
//! `cargo bench -p lodcloth-core --bench points_bench -- [--quick]`

use std::time::Instant;

use lodcloth_core::points::generate::{extreme_point, generate, Shape};
use lodcloth_core::points::knn::Knn;
use lodcloth_core::points::model::{PointModel, Pull, SurfaceParams};
use lodcloth_core::points::normals;
use lodcloth_core::points::simplify::SimplifyOptions;
use lodcloth_core::points::transfer::{NormalUpdate, TransferOptions};
use lodcloth_core::points::PointCloud;
use lodcloth_core::sim::Integrator;

/// Build a pulled sphere model and time `steps` steps: (build s, sim µs/step, transfer µs/step).
fn time_model(
    cloud: &PointCloud,
    target: usize,
    integrator: Integrator,
    normals: NormalUpdate,
    steps: usize,
) -> (PointModel, f64, f64, f64) {
    let top = extreme_point(&cloud.positions, [0.0, 0.0, 1.0]);
    let params = SurfaceParams {
        integrator,
        ..SurfaceParams::default()
    };
    let pull = Pull {
        point: top,
        offset: [0.0, 0.0, 0.3],
        stiffness: 20.0,
        damping: 0.0,
        release: None,
    };
    let t = Instant::now();
    let mut model = PointModel::build(
        cloud,
        Some(&SimplifyOptions {
            target: Some(target),
            ..SimplifyOptions::default()
        }),
        15,
        &params,
        Some(-0.35),
        &[pull],
        &TransferOptions {
            normals,
            ..TransferOptions::default()
        },
        &mut |_, _| {},
    )
    .expect("model");
    let build = t.elapsed().as_secs_f64();
    // Warm up, then time the two halves of a step separately.
    for _ in 0..20 {
        model.step();
        model.update_cloud();
    }
    let (mut sim, mut transfer) = (0.0, 0.0);
    for _ in 0..steps {
        let t0 = Instant::now();
        model.step();
        let t1 = Instant::now();
        model.update_cloud();
        sim += (t1 - t0).as_secs_f64();
        transfer += t1.elapsed().as_secs_f64();
    }
    (model, build, sim * 1e6 / steps as f64, transfer * 1e6 / steps as f64)
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let steps = if quick { 200 } else { 2000 };
    let sphere = generate(Shape::Sphere, 3203, 0.5, 0.0, 1);
    println!("## Time per step on the 3,203-point sphere (transfer and normals included)\n");
    println!("| simulation points | springs | integrator | normals | simulation µs | transfer + normals µs | total µs | paper (P4 2.0 GHz) | speed-up |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for (target, paper) in [(85usize, 0.13), (273, 0.25), (327, 0.32)] {
        for (integrator, normals) in [
            (Integrator::ExplicitEuler, NormalUpdate::Covariance { k: 10 }),
            (Integrator::SymplecticEuler, NormalUpdate::Gradient),
        ] {
            let (model, _, sim, transfer) = time_model(&sphere, target, integrator, normals, steps);
            let total = sim + transfer;
            println!(
                "| {target} | {} | {integrator} | {} | {sim:.1} | {transfer:.1} | {total:.1} | {:.0} ms | {:.0}× |",
                model.sim.topology().spring_count(),
                match normals {
                    NormalUpdate::Gradient => "MLS gradient",
                    NormalUpdate::Covariance { .. } => "covariance (paper)",
                },
                paper * 1e3,
                paper / (total * 1e-6)
            );
        }
    }
    println!();

    let big_n = if quick { 20_000 } else { 100_000 };
    println!("## A {big_n}-point sphere\n");
    let big = generate(Shape::Sphere, big_n, 0.5, 0.0, 2);
    let t = Instant::now();
    let knn = Knn::new(&big.positions);
    let est = normals::estimate_oriented(&big.positions, &knn, 12);
    let normals_s = t.elapsed().as_secs_f64();
    let bad = est
        .iter()
        .zip(big.normals.as_ref().unwrap())
        .filter(|(a, b)| lodcloth_core::sim::vec3::dot(**a, **b) < 0.95)
        .count();
    println!("normals estimated and oriented (k = 12) in {normals_s:.2} s; {bad} of {big_n} off by more than 18°\n");
    println!("| simulation points | build s (simplify + springs + transfer weights) | simulation µs | transfer + normals µs | total µs | reads per point |");
    println!("|---|---|---|---|---|---|");
    for target in [1000usize, 3203, 10_000] {
        let (model, build, sim, transfer) = time_model(
            &big,
            target,
            Integrator::SymplecticEuler,
            NormalUpdate::Gradient,
            steps / 4,
        );
        println!(
            "| {target} | {build:.2} | {sim:.1} | {transfer:.1} | {:.1} | {:.1} |",
            sim + transfer,
            model.transfer.mean_neighbours()
        );
    }
    println!();
}
