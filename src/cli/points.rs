//! `lodcloth points …`: generate test clouds, simulate a simplified cloud and
//! move the full one, and measure accuracy against simplification size.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use tracing::info;

use lodcloth::output::{line_chart_svg, render_points_png, CsvTable, Series, PALETTE};
use lodcloth::points::estimate::{
    fit, rescaled, restart, score, SurfaceFit, SurfaceFitOptions, SurfaceReference, SurfaceScore,
};
use lodcloth::points::generate::{extreme_point, generate, Shape};
use lodcloth::points::knn::Knn;
use lodcloth::points::model::{PointModel, Pull, SurfaceParams};
use lodcloth::points::simplify::SimplifyOptions;
use lodcloth::points::transfer::{NormalUpdate, TransferOptions};
use lodcloth::points::{io, normals, PointCloud};
use lodcloth::sim::vec3::{dist, V3};
use lodcloth::sim::{Integrator, SpringCoeffs};

use crate::{integrator_arg, progress_bar};

#[derive(Subcommand)]
pub enum Points {
    /// Write a test shape: sphere (3,203 points by default, the paper's size),
    /// hat (hemisphere), patch (flat square); --noise makes a scan-like variant
    /// without normals.
    Generate {
        #[arg(long, value_enum)]
        shape: ShapeArg,
        /// Number of points (default: sphere 3203, hat 1600, patch 2500).
        #[arg(long)]
        count: Option<usize>,
        /// Radius (sphere, hat) or side (patch) in metres.
        #[arg(long, default_value_t = 0.5)]
        size: f64,
        /// Displacement along the normal, as a multiple of the mean spacing
        /// (standard deviation); > 0 also drops the normals.
        #[arg(long, default_value_t = 0.0)]
        noise: f64,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output file (.ply or .xyz).
        #[arg(long)]
        out: PathBuf,
    },
    /// Simplify a cloud, simulate the survivors, and write the deformed full
    /// cloud (PLY) at intervals, a CSV report and PNG renders.
    Simulate {
        #[command(flatten)]
        model: ModelArgs,
        /// Number of steps.
        #[arg(long, default_value_t = 2000)]
        steps: u64,
        /// Write the deformed cloud every this many steps (0: only the last).
        #[arg(long, default_value_t = 500)]
        every: u64,
        /// Output directory.
        #[arg(long, default_value = "out/points")]
        out: PathBuf,
    },
    /// Accuracy against simplification size: each size simulated, moved back
    /// to all points and compared with the simulation of every point
    /// (CSV + SVG charts of error vs size and error vs cost).
    Accuracy {
        #[command(flatten)]
        model: ModelArgs,
        /// Simulation point counts, comma separated.
        #[arg(long, value_delimiter = ',', default_values_t = vec![85usize, 150, 273, 327, 600, 1000, 1600])]
        sizes: Vec<usize>,
        /// Simulated seconds.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
        /// Frames compared per simulated second.
        #[arg(long, default_value_t = 50.0)]
        fps: f64,
        /// Also fit the stretch and bend stiffness of every size to the
        /// reference's first half and score it (held-out second half reported).
        #[arg(long)]
        fit: bool,
        #[arg(long, default_value = "out/points-accuracy")]
        out: PathBuf,
    },
}

#[derive(Clone, Copy, ValueEnum)]
pub enum ShapeArg {
    Sphere,
    Hat,
    Patch,
}

impl From<ShapeArg> for Shape {
    fn from(s: ShapeArg) -> Shape {
        match s {
            ShapeArg::Sphere => Shape::Sphere,
            ShapeArg::Hat => Shape::Hat,
            ShapeArg::Patch => Shape::Patch,
        }
    }
}

/// The cloud, its simplification and its physics.
#[derive(Args, Clone)]
pub struct ModelArgs {
    /// Input cloud (.ply, .xyz); normals are estimated when it has none.
    #[arg(long)]
    input: PathBuf,
    /// Number of simulation points to keep.
    #[arg(long)]
    target: Option<usize>,
    /// Remove points whose one-ring diameter is below this (m).
    #[arg(long)]
    threshold: Option<f64>,
    /// Neighbours projected for each one-ring (10–20 in the paper).
    #[arg(long, default_value_t = 15)]
    k: usize,
    #[arg(long, value_parser = integrator_arg, default_value = "symplectic_euler")]
    integrator: Integrator,
    /// Time step (s); default 0.8 × the predicted stability limit.
    #[arg(long)]
    dt: Option<f64>,
    /// Areal density (kg/m²).
    #[arg(long, default_value_t = 0.3)]
    density: f64,
    /// Stretch spring stiffness and damping "K,C".
    #[arg(long, default_value = "50,0.05", value_parser = parse_coeffs)]
    stretch: SpringCoeffs,
    /// Bend spring stiffness and damping "K,C".
    #[arg(long, default_value = "5,0.005", value_parser = parse_coeffs)]
    bend: SpringCoeffs,
    /// Global drag (1/s).
    #[arg(long, default_value_t = 0.5)]
    drag: f64,
    /// Gravity "x,y,z" (m/s², z is up).
    #[arg(long, default_value = "0,0,0", value_parser = parse_v3, allow_hyphen_values = true)]
    gravity: V3,
    /// Pin the simulation points with z at or below this (m).
    #[arg(long, allow_hyphen_values = true)]
    pin_below: Option<f64>,
    /// Point to pull: "top", "bottom" or an index into the input cloud.
    #[arg(long)]
    pull: Option<String>,
    /// Pull target relative to the point's rest position, "dx,dy,dz" (m).
    #[arg(long, default_value = "0,0,0.3", value_parser = parse_v3, allow_hyphen_values = true)]
    pull_offset: V3,
    /// Pull stiffness k_r (N/m).
    #[arg(long, default_value_t = 20.0)]
    pull_k: f64,
    /// Release the pull at this time (s); never when absent.
    #[arg(long)]
    release: Option<f64>,
    /// Recompute normals by covariance (the paper) instead of the MLS gradient.
    #[arg(long)]
    covariance_normals: bool,
}

/// Comma-separated numbers.
fn parse_list(s: &str) -> Result<Vec<f64>, String> {
    s.split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|e| format!("`{x}`: {e}")))
        .collect()
}

fn parse_v3(s: &str) -> Result<V3, String> {
    match parse_list(s)?.as_slice() {
        &[x, y, z] if [x, y, z].iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("expected three finite numbers \"x,y,z\", got `{s}`")),
    }
}

fn parse_coeffs(s: &str) -> Result<SpringCoeffs, String> {
    match parse_list(s)?.as_slice() {
        &[k, c] => Ok(SpringCoeffs { k, c }),
        _ => Err(format!("expected \"K,C\", got `{s}`")),
    }
}

pub fn run(command: Points) -> Result<()> {
    match command {
        Points::Generate {
            shape,
            count,
            size,
            noise,
            seed,
            out,
        } => {
            let shape: Shape = shape.into();
            let count = count.unwrap_or(match shape {
                Shape::Sphere => 3203,
                Shape::Hat => 1600,
                Shape::Patch => 2500,
            });
            if count < 4 {
                bail!("--count must be at least 4, got {count}");
            }
            if !(size > 0.0 && size.is_finite()) {
                bail!("--size must be positive, got {size}");
            }
            if !(noise >= 0.0 && noise.is_finite()) {
                bail!("--noise must be ≥ 0, got {noise}");
            }
            let cloud = generate(shape, count, size, noise, seed);
            if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
            }
            io::write(&out, &cloud)?;
            println!(
                "{} points ({}{}) → {}",
                cloud.len(),
                shape.name(),
                if noise > 0.0 { ", noisy" } else { "" },
                out.display()
            );
            Ok(())
        }
        Points::Simulate {
            model,
            steps,
            every,
            out,
        } => simulate(&model, steps, every, &out),
        Points::Accuracy {
            model,
            sizes,
            seconds,
            fps,
            fit,
            out,
        } => accuracy(&model, &sizes, seconds, fps, fit, &out),
    }
}

/// Mean distance from a point to its nearest neighbour.
fn mean_spacing(points: &[V3]) -> f64 {
    let knn = Knn::new(points);
    let mut nb = Vec::new();
    let mut sum = 0.0;
    for p in points {
        knn.nearest(*p, 2, &mut nb);
        sum += nb.last().map_or(0.0, |r| r.1.sqrt());
    }
    sum / points.len().max(1) as f64
}

/// Read the input and make sure it has oriented normals.
fn load(a: &ModelArgs) -> Result<PointCloud> {
    let mut cloud = io::read(&a.input)?;
    if cloud.len() < 4 {
        bail!(
            "{}: a surface needs at least 4 points, the file has {}",
            a.input.display(),
            cloud.len()
        );
    }
    if cloud.normals.is_none() {
        let t = Instant::now();
        let knn = Knn::new(&cloud.positions);
        cloud.normals = Some(normals::estimate_oriented(&cloud.positions, &knn, 12));
        info!(
            points = cloud.len(),
            seconds = t.elapsed().as_secs_f64(),
            "estimated normals (k = 12)"
        );
    }
    Ok(cloud)
}

fn build(
    a: &ModelArgs,
    cloud: &PointCloud,
    target: Option<usize>,
    threshold: Option<f64>,
    frame_interval: Option<f64>,
) -> Result<PointModel> {
    let params = SurfaceParams {
        frame_interval,
        density: a.density,
        stretch: a.stretch,
        bend: a.bend,
        gravity: a.gravity,
        drag: a.drag,
        integrator: a.integrator,
        dt: a.dt,
        safety: 0.8,
    };
    let pulls = match a.pull.as_deref() {
        None => Vec::new(),
        Some(which) => {
            let point = match which {
                "top" => extreme_point(&cloud.positions, [0.0, 0.0, 1.0]),
                "bottom" => extreme_point(&cloud.positions, [0.0, 0.0, -1.0]),
                i => i.parse::<usize>().ok().filter(|&i| i < cloud.len()).with_context(|| {
                    format!(
                        "--pull `{i}`: expected top, bottom or a point index below {}",
                        cloud.len()
                    )
                })?,
            };
            vec![Pull {
                point,
                offset: a.pull_offset,
                stiffness: a.pull_k,
                damping: 0.0,
                release: a.release,
            }]
        }
    };
    let simplify = (target.is_some() || threshold.is_some()).then_some(SimplifyOptions {
        k: a.k,
        threshold,
        target,
    });
    let transfer = TransferOptions {
        normals: if a.covariance_normals {
            NormalUpdate::Covariance { k: 10 }
        } else {
            NormalUpdate::Gradient
        },
        ..TransferOptions::default()
    };
    let to_remove = target.map_or(cloud.len(), |t| cloud.len().saturating_sub(t)) as u64;
    let bar = progress_bar(to_remove, "simplifying");
    let t = Instant::now();
    let model = PointModel::build(
        cloud,
        simplify.as_ref(),
        a.k,
        &params,
        a.pin_below,
        &pulls,
        &transfer,
        &mut |done, _| bar.set_position(done as u64),
    );
    bar.finish_and_clear();
    let model = model?;
    info!(
        points = cloud.len(),
        simulation_points = model.sim_points(),
        springs = model.sim.topology().spring_count(),
        dt = model.sim.params().dt,
        dt_limit = model.sim.dt_limit(),
        coverage_m = model.simplification.as_ref().map_or(0.0, |s| s.coverage),
        seconds = t.elapsed().as_secs_f64(),
        "surface built"
    );
    Ok(model)
}

fn simulate(a: &ModelArgs, steps: u64, every: u64, out: &Path) -> Result<()> {
    if a.target.is_none() && a.threshold.is_none() {
        bail!("give --target N (simulation points) or --threshold D (m), or both");
    }
    let cloud = load(a)?;
    let mut model = build(a, &cloud, a.target, a.threshold, None)?;
    fs::create_dir_all(out).with_context(|| format!("cannot create output directory {}", out.display()))?;
    // Disc size for the renders: the mean distance to the nearest point.
    let radius = mean_spacing(&cloud.positions);
    render_points_png(
        &out.join("start.png"),
        &model.positions,
        &model.normals,
        &model.kept,
        radius,
        800,
    )?;
    let csv_path = out.join("report.csv");
    let mut csv = CsvTable::create(
        &csv_path,
        &["step", "time", "kinetic_energy", "elastic_energy", "max_displacement"],
    )?;
    let bar = progress_bar(steps, "simulating");
    let started = Instant::now();
    let mut sim_time = 0.0;
    let mut transfer_time = 0.0;
    let mut energy: [Vec<(f64, f64)>; 2] = Default::default();
    let mut written = Vec::new();
    for s in 1..=steps {
        let t0 = Instant::now();
        let r = model.step();
        let t1 = Instant::now();
        if !r.finite {
            bar.abandon();
            bail!(
                "the surface diverged at step {s} (t = {:.4} s); lower --dt (predicted limit {:.3e} s) or use --integrator implicit-euler",
                r.time,
                model.sim.dt_limit()
            );
        }
        model.update_cloud();
        sim_time += (t1 - t0).as_secs_f64();
        transfer_time += t1.elapsed().as_secs_f64();
        let frame = every > 0 && s % every == 0;
        if frame || s == steps {
            let max_disp = model
                .positions
                .iter()
                .zip(&cloud.positions)
                .map(|(p, q)| dist(*p, *q))
                .fold(0.0, f64::max);
            csv.row(&[
                s.to_string(),
                r.time.to_string(),
                r.kinetic_energy.to_string(),
                r.elastic_energy.to_string(),
                max_disp.to_string(),
            ])?;
            energy[0].push((r.time, r.kinetic_energy));
            energy[1].push((r.time, r.elastic_energy));
            let path = out.join(format!("cloud_{s:06}.ply"));
            io::write(&path, &model.cloud())?;
            written.push(path);
        }
        bar.set_position(s);
    }
    bar.finish_and_clear();
    csv.finish()?;
    render_points_png(
        &out.join("final.png"),
        &model.positions,
        &model.normals,
        &model.kept,
        radius,
        800,
    )?;
    line_chart_svg(
        &out.join("energy.svg"),
        &format!("{} → {} points: energy", cloud.len(), model.sim_points()),
        "time (s)",
        "energy (J)",
        &[
            Series {
                name: "kinetic",
                points: energy[0].clone(),
                markers: false,
                color: PALETTE[0],
            },
            Series {
                name: "elastic",
                points: energy[1].clone(),
                markers: false,
                color: PALETTE[1],
            },
        ],
        false,
        false,
    )?;
    let wall = started.elapsed().as_secs_f64();
    println!(
        "cloud            {} points → {} simulation points",
        cloud.len(),
        model.sim_points()
    );
    println!(
        "springs          {} ({} per point), dt = {:.3e} s (limit {:.3e} s), {}",
        model.sim.topology().spring_count(),
        model.sim.topology().spring_count() / model.sim_points().max(1),
        model.sim.params().dt,
        model.sim.dt_limit(),
        model.sim.params().integrator
    );
    println!(
        "per step         {:.1} µs simulation + {:.1} µs transfer and normals ({:.2} s wall for {steps} steps)",
        sim_time * 1e6 / steps as f64,
        transfer_time * 1e6 / steps as f64,
        wall
    );
    println!(
        "wrote            {} clouds, report.csv, energy.svg, start.png, final.png in {}",
        written.len(),
        out.display()
    );
    Ok(())
}

fn accuracy(a: &ModelArgs, sizes: &[usize], seconds: f64, fps: f64, with_fit: bool, out: &Path) -> Result<()> {
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
