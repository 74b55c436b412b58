//! `lodcloth-lab table1`: the paper's Table 1 and beyond, with its tables, chart and error maps.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use tracing::info;

use lodcloth::estimate::{Method, Reference};
use lodcloth::output::{line_chart_svg, CsvTable, Series, PALETTE};
use lodcloth::plan::GridLevel;
use lodcloth::scene::{MassConvention, Scene};
use lodcloth_lab::error_map::{error_map_svg, ClothPanel};
use lodcloth_lab::experiments::lod::{table1_scene, Table1Options, Table1Row, Variant, TABLE1_VARIANTS};

use super::{header_around, log_line, reference_for, row_around, Common, PAPER_TABLE1, SHORT_WINDOW};

pub(super) fn table1(common: &Common, levels: &[GridLevel]) -> Result<()> {
    let out = common.out("out/table1")?;
    let spec = common.spec()?;
    let scenes = common.scenes()?;
    let frames = (spec.frames / spec.metric_stride) as usize;
    let map_level = if levels.contains(&GridLevel::Long(48)) {
        GridLevel::Long(48)
    } else {
        levels[levels.len() / 2]
    };
    let options = Table1Options {
        levels: levels.to_vec(),
        spec,
        variants: TABLE1_VARIANTS
            .iter()
            .map(|&v| Variant {
                reading: common.reading,
                ..v
            })
            .collect(),
        fit: common.fit(frames)?,
        dt_margin: 0.75,
        map_level,
        short_window: SHORT_WINDOW,
    };
    let started = Instant::now();
    let estimator = common.estimator()?;
    let mut rows: Vec<Table1Row> = Vec::new();
    let mut ref_costs = Vec::new();
    for scene in &scenes {
        let (reference, cost) = reference_for(scene, spec)?;
        ref_costs.push((scene.name.clone(), cost));
        let scene_rows = table1_scene(scene, &reference, &options, &estimator, &mut log_line)?;
        write_error_maps(&out, scene, &reference, &scene_rows, map_level)?;
        rows.extend(scene_rows);
        write_table1(&out, &rows, &ref_costs, levels, &scenes, common)?;
    }
    info!(
        "table1 done in {:.0} s: {}",
        started.elapsed().as_secs_f64(),
        out.join("table1.md").display()
    );
    Ok(())
}

pub(super) fn write_table1(
    out: &Path,
    rows: &[Table1Row],
    ref_costs: &[(String, f64)],
    levels: &[GridLevel],
    scenes: &[Scene],
    common: &Common,
) -> Result<()> {
    fs::write(out.join("table1.csv"), table1_csv(rows)).context("writing table1.csv")?;
    let labels: Vec<String> = TABLE1_VARIANTS
        .iter()
        .map(|&v| {
            Variant {
                reading: common.reading,
                ..v
            }
            .label()
        })
        .collect();
    let mut md = table1_by_level(rows, &labels, levels, scenes, common);
    md.push_str(&table1_by_scene(rows, ref_costs));
    fs::write(out.join("table1.md"), md).context("writing table1.md")?;
    table1_chart(out, rows, &labels, levels)
}

/// Every row of Table 1, one line each.
pub(super) fn table1_csv(rows: &[Table1Row]) -> String {
    let mut csv = CsvTable::in_memory(&header_around(
        &["scene", "level", "nodes", "reduction", "variant", "method", "mass"],
        &[
            "dt",
            "dt_over_limit",
            "mean",
            "held_out_mean",
            "short_held_out_mean",
            "p95",
            "max",
            "first_quarter",
            "last_quarter",
            "worst_time",
            "worst_frame_mean",
            "estimate_s",
            "cost_s_per_s",
            "diverged",
            "notes",
        ],
    ));
    for r in rows {
        let before = vec![
            r.scene.clone(),
            format!("{}x{}", r.nx, r.ny),
            r.nodes.to_string(),
            format!("{:.4}", r.reduction),
            r.variant.label(),
            r.variant.method.to_string(),
            r.variant.mass.name().to_string(),
        ];
        let after = vec![
            format!("{:e}", r.dt),
            format!("{:.3}", r.dt_ratio),
            format!("{:.6}", r.all.mean),
            format!("{:.6}", r.held_out_mean),
            format!("{:.6}", r.short_held_out_mean),
            format!("{:.6}", r.all.p95),
            format!("{:.6}", r.all.max),
            format!("{:.6}", r.all.first_quarter),
            format!("{:.6}", r.all.last_quarter),
            format!("{:.4}", r.all.worst_time),
            format!("{:.6}", r.all.worst_frame_mean),
            format!("{:.2}", r.estimate_seconds),
            format!("{:.4}", r.cost),
            r.all.diverged.to_string(),
            r.notes.clone(),
        ];
        csv.row(&row_around(before, &r.material, after))
            .expect("a row per header column");
    }
    csv.into_text()
}

/// The paper's same / BCD / GKD at `level`, or a dash where its table has
/// no row.
pub(super) fn paper_cell(level: GridLevel) -> String {
    PAPER_TABLE1
        .iter()
        .find(|p| Some(p.0) == level.square())
        .map_or("—".to_string(), |p| format!("{} / {} / {}", p.1, p.2, p.3))
}

/// The mean over scenes of `f` for one level and variant.
pub(super) fn mean_of(rows: &[Table1Row], level: GridLevel, label: &str, f: impl Fn(&Table1Row) -> f64) -> f64 {
    let v: Vec<f64> = rows
        .iter()
        .filter(|r| r.level == level && r.variant.label() == label)
        .map(f)
        .collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Table 1 as the paper prints it: per level, each variant's mean over the
/// scenes (all frames, then held-out), beside the paper's numbers.
pub(super) fn table1_by_level(
    rows: &[Table1Row],
    labels: &[String],
    levels: &[GridLevel],
    scenes: &[Scene],
    common: &Common,
) -> String {
    let scenes_done: Vec<&str> = scenes
        .iter()
        .map(|s| s.name.as_str())
        .filter(|n| rows.iter().any(|r| r.scene == *n))
        .collect();
    let mut md = String::new();
    let _ = writeln!(
        md,
        "Mean displacement error (% of O_max, Sung eq. 9) averaged over {} — reference {}, {} frames, metric every {} frames.\n\nCommand: `lodcloth-lab table1{}`\n",
        scenes_done.join(", "),
        scenes.first().map_or(String::new(), |s| format!("{}×{}", s.nx, s.ny)),
        common.frames,
        common.metric_stride,
        if common.quick { " --quick" } else { "" }
    );
    let short_title = format!(
        "Held-out frames, short horizon (the level restarted from the reference's mapped state every {SHORT_WINDOW} s)"
    );
    for (title, which) in [
        ("All frames (fit's training half included)", 0),
        ("Held-out frames (second half of the run: fit never saw them)", 1),
        (short_title.as_str(), 2),
    ] {
        let _ = writeln!(md, "### {title}\n");
        let _ = writeln!(
            md,
            "| coarse | reduction | {} | paper same / BCD / GKD |",
            labels.join(" | ")
        );
        let _ = writeln!(md, "|---|---|{}---|", "---|".repeat(labels.len()));
        for &level in levels {
            if !rows.iter().any(|r| r.level == level) {
                continue;
            }
            let first = rows.iter().find(|r| r.level == level);
            let reduction = first.map_or(0.0, |r| r.reduction);
            // The grid itself when every scene resolves the level alike.
            let name = match first {
                Some(f)
                    if rows
                        .iter()
                        .filter(|r| r.level == level)
                        .all(|r| (r.nx, r.ny) == (f.nx, f.ny)) =>
                {
                    format!("{}×{}", f.nx, f.ny)
                }
                _ => format!("{level} (aspect kept)"),
            };
            let cells: Vec<String> = labels
                .iter()
                .map(|l| {
                    let v = mean_of(rows, level, l, |r| match which {
                        0 => r.all.mean,
                        1 => r.held_out_mean,
                        _ => r.short_held_out_mean,
                    });
                    format!("{:.2}", 100.0 * v)
                })
                .collect();
            let paper = paper_cell(level);
            let _ = writeln!(
                md,
                "| {name} | {:.0}% | {} | {paper} |",
                100.0 * reduction,
                cells.join(" | ")
            );
        }
        let _ = writeln!(md);
    }
    md
}

/// Per scene and level: fit against the paper's GKD, its tail, drift and
/// cost; then each reference's cost.
pub(super) fn table1_by_scene(rows: &[Table1Row], ref_costs: &[(String, f64)]) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "### Per scene (all frames / held-out), fit and the paper's GKD\n");
    let _ = writeln!(md, "| scene | coarse | gkd/per-node | fit/lumped | fit p95 | fit last/first quarter | estimation s (fit) | cost s/s (fit) |");
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|");
    for r in rows.iter().filter(|r| r.variant.method == Method::Fit) {
        let gkd = rows.iter().find(|g| {
            g.scene == r.scene
                && g.level == r.level
                && g.variant.method == Method::Gkd
                && g.variant.mass == MassConvention::PerNode
        });
        let _ = writeln!(
            md,
            "| {} | {}×{} | {} | {:.2} / {:.2} | {:.2} | {:.2} | {:.0} | {:.3} |",
            r.scene,
            r.nx,
            r.ny,
            gkd.map_or("—".into(), |g| format!(
                "{:.2} / {:.2}",
                100.0 * g.all.mean,
                100.0 * g.held_out_mean
            )),
            100.0 * r.all.mean,
            100.0 * r.held_out_mean,
            100.0 * r.all.p95,
            r.all.last_quarter / r.all.first_quarter.max(f64::MIN_POSITIVE),
            r.estimate_seconds,
            r.cost
        );
    }
    let _ = writeln!(md, "\nReference cost (wall s per simulated s):");
    for (name, c) in ref_costs {
        let _ = writeln!(md, "- {name}: {c:.3}");
    }
    md
}

/// Held-out mean error against node reduction, one line per variant.
pub(super) fn table1_chart(out: &Path, rows: &[Table1Row], labels: &[String], levels: &[GridLevel]) -> Result<()> {
    let series: Vec<Series<'_>> = labels
        .iter()
        .enumerate()
        .map(|(i, l)| Series {
            name: l,
            points: levels
                .iter()
                .filter(|&&lv| rows.iter().any(|r| r.level == lv))
                .map(|&lv| {
                    let red = rows.iter().find(|r| r.level == lv).map_or(0.0, |r| r.reduction);
                    (100.0 * red, 100.0 * mean_of(rows, lv, l, |r| r.held_out_mean))
                })
                .collect(),
            markers: false,
            color: PALETTE[i % PALETTE.len()],
        })
        .collect();
    if series.iter().any(|s| !s.points.is_empty()) {
        line_chart_svg(
            &out.join("error_vs_reduction.svg"),
            "Held-out mean error vs node reduction (mean over scenes)",
            "node reduction (%)",
            "mean error (% of O_max)",
            &series,
            false,
            true,
        )?;
    }
    Ok(())
}

pub(super) fn write_error_maps(
    out: &Path,
    scene: &Scene,
    reference: &Reference,
    rows: &[Table1Row],
    level: GridLevel,
) -> Result<()> {
    let (nx, ny) = level.resolve(scene.width, scene.height);
    let chosen = [
        (Method::SameSpring, MassConvention::PerNode),
        (Method::Bcd, MassConvention::PerNode),
        (Method::Gkd, MassConvention::PerNode),
        (Method::Fit, MassConvention::Lumped),
    ];
    let maps: Vec<&Table1Row> = rows
        .iter()
        .filter(|r| r.level == level && chosen.contains(&(r.variant.method, r.variant.mass)) && !r.all.diverged)
        .collect();
    let scale = maps
        .iter()
        .flat_map(|r| r.all.worst_frame_nodes.iter().copied())
        .fold(0.0, f64::max)
        .max(1e-6);
    for r in maps {
        let frame = reference
            .frame_times
            .iter()
            .position(|&t| (t - r.all.worst_time).abs() < 1e-9)
            .unwrap_or(0);
        let ref_pos: Vec<f64> = reference.frames[frame].iter().map(|&x| f64::from(x)).collect();
        let coarse = lodcloth::sim::Topology::grid(scene.shape(nx, ny), scene.orientation);
        let panels = [
            ClothPanel {
                title: format!("reference {}×{}", scene.nx, scene.ny),
                topology: &reference.topology,
                pos: &ref_pos,
                values: None,
            },
            ClothPanel {
                title: format!(
                    "{} {nx}×{ny}: mean {:.2}%",
                    r.variant.label(),
                    100.0 * r.all.worst_frame_mean
                ),
                topology: &coarse,
                pos: &r.all.worst_positions,
                values: Some(&r.all.worst_frame_nodes),
            },
        ];
        let path = out.join(format!(
            "errormap_{}_{level}_{}.svg",
            scene.name,
            r.variant.label().replace('/', "_")
        ));
        error_map_svg(
            &path,
            &format!("{} — worst frame t = {:.3} s", scene.name, r.all.worst_time),
            &panels,
            scale,
            420,
        )?;
    }
    Ok(())
}
