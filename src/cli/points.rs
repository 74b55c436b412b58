//! `lodcloth points …`: generate test clouds, and simulate a simplified cloud
//! and move the full one. (Accuracy against simplification size is a study:
//! `lodcloth-lab points-accuracy`.)

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Subcommand, ValueEnum};

use lodcloth::args::points::{build, load, ModelArgs};
use lodcloth::args::progress_bar;
use lodcloth::output::{line_chart_svg, render_points_png, CsvTable, Series, PALETTE};
use lodcloth::points::generate::{generate, Shape};
use lodcloth::points::io;
use lodcloth::points::knn::Knn;
use lodcloth::sim::vec3::{dist, V3};

// Parsed once per run: boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
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
