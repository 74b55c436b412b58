//! `lodcloth-lab stability`: each integrator's stability threshold measured
//! by bisection over dt and stiffness/mass ratios, against its prediction.

use std::fs;
use std::path::Path;

use anyhow::{bail, Context, Result};
use tracing::info;

use lodcloth::args::{grid_scene, progress_bar};
use lodcloth::output::{line_chart_svg, CsvTable, Series, PALETTE};
use lodcloth::sim::Integrator;
use lodcloth_lab::experiments::{stability_sweep, StabilityRow, StabilitySweep};

pub fn stability(
    scene_path: &Path,
    sizes: Vec<usize>,
    factors: Vec<f64>,
    steps: u32,
    bisections: u32,
    out: &Path,
) -> Result<()> {
    let scene = grid_scene(scene_path)?;
    if sizes.iter().any(|&n| n < 2) {
        bail!("--sizes: every size must be at least 2");
    }
    if factors.iter().any(|f| !(f.is_finite() && *f > 0.0)) {
        bail!("--factors: every stiffness factor must be positive");
    }
    fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let cfg = StabilitySweep {
        sizes,
        stiffness_factors: factors,
        integrators: Integrator::ALL.to_vec(),
        material: scene.params.material,
        side: scene.width,
        areal_density: scene.areal_density,
        steps,
        bisections,
    };
    let total = cfg.integrators.len() * cfg.sizes.len() * cfg.stiffness_factors.len();
    let bar = progress_bar(total as u64, "stability sweep");
    let rows = stability_sweep(&cfg, &mut |done, total| {
        bar.set_position(done as u64);
        if bar.is_hidden() {
            info!("stability sweep: {done}/{total}");
        }
    });
    bar.finish_and_clear();

    let csv_path = out.join("stability.csv");
    let mut csv = CsvTable::create(
        &csv_path,
        &[
            "integrator",
            "n",
            "stiffness_factor",
            "omega_gershgorin",
            "omega_max",
            "damping_rate",
            "predicted_dt",
            "measured_stable_dt",
            "measured_unstable_dt",
            "measured_over_predicted",
        ],
    )?;
    println!(
        "{:<17} {:>4} {:>7} {:>10} {:>12} {:>12} {:>8}",
        "integrator", "n", "k×", "ω_max", "predicted dt", "measured dt", "ratio"
    );
    for r in &rows {
        // Implicit Euler has no predicted limit: no ratio (NaN in the CSV).
        let ratio = if r.predicted_dt.is_finite() {
            r.measured_dt() / r.predicted_dt
        } else {
            f64::NAN
        };
        csv.row(&[
            r.integrator.to_string(),
            r.n.to_string(),
            r.stiffness_factor.to_string(),
            format!("{:.6e}", r.omega_gershgorin),
            format!("{:.6e}", r.omega_max),
            format!("{:.6e}", r.damping_rate),
            format!("{:.6e}", r.predicted_dt),
            format!("{:.6e}", r.measured_stable),
            format!("{:.6e}", r.measured_unstable),
            format!("{ratio:.4}"),
        ])?;
        let measured = if r.measured_unstable.is_finite() {
            format!("{:.3e}", r.measured_dt())
        } else {
            format!("≥{:.2e}", r.measured_stable)
        };
        println!(
            "{:<17} {:>4} {:>7} {:>10.0} {:>12.3e} {:>12} {:>8.3}",
            r.integrator.name(),
            r.n,
            r.stiffness_factor,
            r.omega_max,
            r.predicted_dt,
            measured,
            ratio
        );
    }
    csv.finish()?;

    // Chart: measured threshold against ω_max, with each integrator's
    // prediction as a line (implicit Euler: lower bounds only).
    let mut series = Vec::new();
    let names: Vec<String> = Integrator::ALL.iter().map(|i| i.name().to_string()).collect();
    let pred_names: Vec<String> = names.iter().map(|n| format!("{n} predicted")).collect();
    for (i, integrator) in Integrator::ALL.iter().enumerate() {
        let mut of: Vec<&StabilityRow> = rows.iter().filter(|r| r.integrator == *integrator).collect();
        of.sort_by(|a, b| a.omega_max.total_cmp(&b.omega_max));
        let color = PALETTE[i];
        series.push(Series {
            name: &pred_names[i],
            points: of.iter().map(|r| (r.omega_max, r.predicted_dt)).collect(),
            markers: false,
            color,
        });
        series.push(Series {
            name: &names[i],
            points: of.iter().map(|r| (r.omega_max, r.measured_dt())).collect(),
            markers: true,
            color,
        });
    }
    let svg = out.join("stability.svg");
    line_chart_svg(
        &svg,
        "Largest stable dt: predicted (lines) vs measured (dots)",
        "ω_max (rad/s)",
        "dt (s)",
        &series,
        true,
        true,
    )?;
    println!("wrote {} and {}", csv_path.display(), svg.display());
    Ok(())
}
