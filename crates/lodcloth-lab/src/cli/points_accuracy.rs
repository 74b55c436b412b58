//! `lodcloth-lab points-accuracy`: a point-sampled surface's accuracy against
//! its simplification size, each size simulated, moved back to every point
//! and compared with the simulation of every point.

use std::fs;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use tracing::info;

use lodcloth::args::points::{build, load, ModelArgs};
use lodcloth::output::{line_chart_svg, CsvTable, Series, PALETTE};
use lodcloth::points::estimate::{
    fit, rescaled, restart, score, SurfaceFit, SurfaceFitOptions, SurfaceReference, SurfaceScore,
};
use lodcloth::points::model::PointModel;

pub fn accuracy(a: &ModelArgs, sizes: &[usize], seconds: f64, fps: f64, with_fit: bool, out: &Path) -> Result<()> {
    if !(seconds > 0.0 && seconds.is_finite() && fps > 0.0 && fps.is_finite()) {
        bail!("--seconds and --fps must be positive");
    }
    let cloud = load(a)?;
    fs::create_dir_all(out).with_context(|| format!("cannot create output directory {}", out.display()))?;
    let frames = (seconds * fps).round() as usize;
    let interval = 1.0 / fps;
    // Every model runs at its own stable dt; frames are compared at common
    // times (each model's dt divides the frame interval).
    if a.dt.is_some() {
        bail!("accuracy picks each model's dt (0.8 × its stability limit, dividing the frame interval); drop --dt");
    }
    info!(points = cloud.len(), "reference: every point simulated");
    let mut reference_model = build(a, &cloud, None, None, Some(interval))?;
    let t = Instant::now();
    let reference = SurfaceReference::record(&mut reference_model, frames, interval)
        .context("recording the all-points reference (add a --pull or --gravity so there is motion)")?;
    let ref_cost = t.elapsed().as_secs_f64() / seconds;
    let csv_path = out.join("accuracy.csv");
    let mut csv = CsvTable::create(
        &csv_path,
        &[
            "sim_points",
            "springs",
            "dt",
            "wall_per_sim_second",
            "error_mean",
            "error_max",
            "fit_error_mean",
            "fit_error_max",
            "fit_held_out_mean",
            "stretch_scale",
            "bend_scale",
            "fit_seconds",
        ],
    )?;
    let reference_row = [
        cloud.len().to_string(),
        reference_model.sim.topology().spring_count().to_string(),
        reference_model.sim.params().dt.to_string(),
        ref_cost.to_string(),
    ];
    csv.row(
        &[
            &reference_row[..],
            &["0", "0", "0", "0", "0", "1", "1", "0"].map(String::from),
        ]
        .concat(),
    )?;
    let mut same_by_size = Vec::new();
    let mut same_by_cost = Vec::new();
    let mut fit_by_size = Vec::new();
    let mut fit_by_cost = Vec::new();
    println!(
        "| simulation points | springs | dt (ms) | wall ms per simulated s | mean error | max error |{}",
        if with_fit {
            " fit: mean (held-out half) | fit: max | stretch, bend scale | fit s |"
        } else {
            ""
        }
    );
    println!(
        "|---|---|---|---|---|---|{}",
        if with_fit { "---|---|---|---|" } else { "" }
    );
    println!(
        "| {} (reference) | {} | {:.3} | {:.0} | 0 | 0 |{}",
        cloud.len(),
        reference_model.sim.topology().spring_count(),
        reference_model.sim.params().dt * 1e3,
        ref_cost * 1e3,
        if with_fit { " | | | |" } else { "" }
    );
    for &size in sizes {
        if size >= cloud.len() {
            continue;
        }
        let mut model = build(a, &cloud, Some(size), None, Some(interval))?;
        let t = Instant::now();
        let fresh = restart(&model)?;
        let same = score(&mut model, fresh, &reference, 0..frames)?;
        let cost = t.elapsed().as_secs_f64() / seconds;
        if !same.finite {
            bail!("the {size}-point model diverged");
        }
        let springs = model.sim.topology().spring_count();
        let dt = model.sim.params().dt;
        same_by_size.push((size as f64, 100.0 * same.mean));
        same_by_cost.push((cost * 1e3, 100.0 * same.mean));
        let mut row = format!(
            "| {size} | {springs} | {:.3} | {:.0} | {:.2}% | {:.2}% |",
            dt * 1e3,
            cost * 1e3,
            100.0 * same.mean,
            100.0 * same.max
        );
        let mut fit_cols = ["0", "0", "0", "1", "1", "0"].map(String::from);
        if with_fit {
            let (fitted, all, held, fit_seconds) = fit_and_score(&mut model, &reference, frames)?;
            row += &format!(
                " {:.2}% ({:.2}%) | {:.2}% | {:.2}, {:.2} | {fit_seconds:.1} |",
                100.0 * all.mean,
                100.0 * held.mean,
                100.0 * all.max,
                fitted.stretch_scale,
                fitted.bend_scale
            );
            fit_cols = [
                all.mean.to_string(),
                all.max.to_string(),
                held.mean.to_string(),
                fitted.stretch_scale.to_string(),
                fitted.bend_scale.to_string(),
                fit_seconds.to_string(),
            ];
            fit_by_size.push((size as f64, 100.0 * all.mean));
            fit_by_cost.push((cost * 1e3, 100.0 * all.mean));
        }
        let same_cols = [
            size.to_string(),
            springs.to_string(),
            dt.to_string(),
            cost.to_string(),
            same.mean.to_string(),
            same.max.to_string(),
        ];
        csv.row(&[&same_cols[..], &fit_cols[..]].concat())?;
        println!("{row}");
    }
    csv.finish()?;
    let points = cloud.len();
    accuracy_chart(out, "error_vs_size.svg", points, Axis::Size, same_by_size, fit_by_size)?;
    accuracy_chart(out, "error_vs_cost.svg", points, Axis::Cost, same_by_cost, fit_by_cost)?;
    println!(
        "wrote accuracy.csv, error_vs_size.svg, error_vs_cost.svg in {}",
        out.display()
    );
    Ok(())
}

/// Fit a simplified model's stretch and bend stiffness on the first half
/// of the run; its fit and how it scores on every frame and on the held-out
/// half, and the fit's wall time (s).
fn fit_and_score(
    model: &mut PointModel,
    reference: &SurfaceReference,
    frames: usize,
) -> Result<(SurfaceFit, SurfaceScore, SurfaceScore, f64)> {
    let t = Instant::now();
    let half = frames / 2;
    let options = SurfaceFitOptions {
        train: 0..half,
        ..SurfaceFitOptions::default()
    };
    let fitted = fit(model, reference, &options, &mut |_| {})?;
    let fit_seconds = t.elapsed().as_secs_f64();
    let sim = rescaled(model, fitted.stretch_scale, fitted.bend_scale, f64::INFINITY)?.expect("no bound");
    let all = score(model, sim.clone(), reference, 0..frames)?;
    let held = score(model, sim, reference, half..frames)?;
    Ok((fitted, all, held, fit_seconds))
}

/// The horizontal axis of an accuracy chart.
#[derive(Clone, Copy)]
enum Axis {
    /// Simulated points.
    Size,
    /// Wall ms per simulated second.
    Cost,
}

/// Mean error of the simplified simulations against size or cost, with
/// and without fitted stiffness.
fn accuracy_chart(
    out: &Path,
    file: &str,
    points: usize,
    axis: Axis,
    same: Vec<(f64, f64)>,
    fitted: Vec<(f64, f64)>,
) -> Result<()> {
    let mut series = vec![Series {
        name: "same coefficients",
        points: same,
        markers: true,
        color: PALETTE[0],
    }];
    if !fitted.is_empty() {
        series.push(Series {
            name: "fitted stretch and bend stiffness",
            points: fitted,
            markers: true,
            color: PALETTE[1],
        });
    }
    let (title, x_label, y_label) = match axis {
        Axis::Size => (
            format!("{points} points: error of the simplified simulation"),
            "simulation points",
            "mean displacement error (% of max displacement)",
        ),
        Axis::Cost => (
            format!("{points} points: speed against accuracy"),
            "wall ms per simulated second (cloud moved every frame)",
            "mean displacement error (%)",
        ),
    };
    line_chart_svg(&out.join(file), &title, x_label, y_label, &series, true, true)?;
    Ok(())
}
