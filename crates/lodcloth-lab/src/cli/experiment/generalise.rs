//! `lodcloth-lab generalise`: every estimator over the suite, held-out time and scenes, both horizons.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;

use anyhow::{Context, Result};
use tracing::info;

use lodcloth::estimate::Method;
use lodcloth::output::{line_chart_svg, CsvTable, Series, PALETTE};
use lodcloth::plan::GridLevel;
use lodcloth_lab::experiments::generalise::{
    draw_offset, reference_draw, suite, HeldOut, Spread, SuiteOptions, SuiteRow,
};

use super::{header_around, log_line, reference_for, row_around, Common, PAPER_SCENES, SHORT_WINDOW, SUITE_SCENES};

#[allow(clippy::too_many_arguments)]
pub(super) fn generalise_cmd(
    common: &Common,
    level: GridLevel,
    methods: &[Method],
    floor_perturbation: f64,
    bend_scale: (f64, f64),
    modal: Option<std::ops::Range<usize>>,
    settle: Option<f64>,
    draws: usize,
) -> Result<()> {
    let out = common.out("out/generalise")?;
    let spec = common.spec()?;
    let defaults: Vec<&str> = PAPER_SCENES.iter().chain(&SUITE_SCENES).copied().collect();
    let scenes = common.scenes_or(&defaults)?;
    anyhow::ensure!(!scenes.is_empty(), "no scene");
    let estimator = common.estimator()?;
    let mut rows: Vec<(usize, SuiteRow)> = Vec::new();
    for draw in 0..draws {
        if draws > 1 {
            info!(
                "reference draw {}/{draws}: every stiffness × {}",
                draw + 1,
                1.0 + draw_offset(draw) * floor_perturbation
            );
        }
        // One draw's references at a time: they are the largest thing held.
        let mut pairs = Vec::new();
        for scene in &scenes {
            let drawn = reference_draw(scene, draw, floor_perturbation);
            let (reference, _) = reference_for(&drawn, spec)?;
            pairs.push((drawn, reference));
        }
        let frames = pairs[0].1.frames.len();
        let options = SuiteOptions {
            level,
            methods: methods.to_vec(),
            fit: common.fit(frames)?,
            train_fraction: common.train_fraction,
            short_window: SHORT_WINDOW,
            floor_perturbation,
            bend_scale,
            modal: modal.clone(),
            settle,
        };
        let mut log = |line: String| {
            if draws > 1 {
                log_line(format!("[draw {}] {line}", draw + 1))
            } else {
                log_line(line)
            }
        };
        rows.extend(
            suite(&pairs, &options, &estimator, &mut log)?
                .into_iter()
                .map(|r| (draw, r)),
        );
    }
    fs::write(out.join("generalise.csv"), suite_csv(&rows, floor_perturbation)).context("writing generalise.csv")?;
    let md = suite_md(&rows, methods, level, common, floor_perturbation, draws);
    fs::write(out.join("generalise.md"), &md).context("writing generalise.md")?;
    suite_chart(&out, &rows, methods)?;
    println!("{md}");
    Ok(())
}

/// One row per reference draw × scene × method; `draw` 0 is the scene as
/// written, draw d's stiffnesses × (1 + `draw_offset` · `eps`).
pub(super) fn suite_csv(rows: &[(usize, SuiteRow)], eps: f64) -> String {
    let mut csv = CsvTable::in_memory(&header_around(
        &["draw", "stiffness_factor", "scene", "level", "reduction", "method"],
        &[
            "estimate_s",
            "mean",
            "p95",
            "last_quarter",
            "short_mean",
            "short_p95",
            "transferred_mean",
            "transferred_p95",
            "transferred_last_quarter",
            "transferred_short_mean",
            "transferred_short_p95",
            "floor_mean",
            "floor_p95",
            "floor_last_quarter",
            "floor_min",
            "floor_max",
            "notes",
        ],
    ));
    let f6 = |v: f64| format!("{v:.6}");
    for (draw, r) in rows {
        let t = r.transferred;
        let opt = |f: fn(&HeldOut) -> f64| t.as_ref().map_or(String::new(), |h| f6(f(h)));
        let before = vec![
            draw.to_string(),
            (1.0 + draw_offset(*draw) * eps).to_string(),
            r.scene.clone(),
            r.level.to_string(),
            format!("{:.4}", r.reduction),
            r.method.to_string(),
        ];
        let after = vec![
            format!("{:.1}", r.estimate_seconds),
            f6(r.own.mean),
            f6(r.own.p95),
            f6(r.own.last_quarter),
            f6(r.own.short_mean),
            f6(r.own.short_p95),
            opt(|h| h.mean),
            opt(|h| h.p95),
            opt(|h| h.last_quarter),
            opt(|h| h.short_mean),
            opt(|h| h.short_p95),
            f6(r.floor.mean),
            f6(r.floor.p95),
            f6(r.floor.last_quarter),
            f6(r.floor.min),
            f6(r.floor.max),
            r.notes.clone(),
        ];
        csv.row(&row_around(before, &r.material, after))
            .expect("a row per header column");
    }
    csv.into_text()
}

/// Per scene (and reference draw), each method's held-out mean / p95 /
/// last quarter, long and short horizon, own and transferred; over several
/// draws, each scene × method's mean, spread and range over them; then the
/// means over the scenes (and draws).
pub(super) fn suite_md(
    rows: &[(usize, SuiteRow)],
    methods: &[Method],
    level: GridLevel,
    common: &Common,
    eps: f64,
    draws: usize,
) -> String {
    let pct = |x: f64| format!("{:.2}", 100.0 * x);
    let drawn = draws > 1;
    let mut md = format!(
        "Held-out error (% of O_max) at level {level} (N along each cloth's longer side), trained on the first {:.0} % of each run. \
         Long horizon: one run from rest (Sung eq. 9); short: restarted from the reference every {SHORT_WINDOW} s. \
         'Other scenes': the median of the other scenes' K and C corrections (estimate / reference) applied to this scene's reference coefficients. \
         Chaos floor: three twins of the reference itself (every K × (1 ± {eps:e}), every C × (1 + {eps:e})), long horizon, their mean and range; a long-horizon error near it is chaos, not the level.{}\n\n\
         Command: `{}`\n\n",
        100.0 * common.train_fraction,
        if drawn {
            format!(
                " Reference draws: each scene's reference recorded {draws} times, every stiffness × (1 + d · {eps:e}), d = 0, +1, −1, +2, …; \
                 each draw is scored on its own recording."
            )
        } else {
            String::new()
        },
        command_line()
    );
    let _ = writeln!(
        md,
        "| {}scene | level | method | mean | p95 | last quarter | short-horizon mean | short p95 | other scenes: mean | other scenes: short mean | chaos floor: mean (range) |",
        if drawn { "draw | " } else { "" }
    );
    let _ = writeln!(
        md,
        "|{}---|---|---|---|---|---|---|---|---|---|---|",
        if drawn { "---|" } else { "" }
    );
    for (draw, r) in rows {
        let _ = writeln!(
            md,
            "| {}{} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} ({}–{}) |",
            if drawn { format!("{draw} | ") } else { String::new() },
            r.scene,
            r.level,
            r.method,
            pct(r.own.mean),
            pct(r.own.p95),
            pct(r.own.last_quarter),
            pct(r.own.short_mean),
            pct(r.own.short_p95),
            r.transferred.map_or("—".into(), |t| pct(t.mean)),
            r.transferred.map_or("—".into(), |t| pct(t.short_mean)),
            pct(r.floor.mean),
            pct(r.floor.min),
            pct(r.floor.max),
        );
    }
    if drawn {
        let _ = writeln!(
            md,
            "\nOver the {draws} reference draws (mean ± sample sd, range):\n\n\
             | scene | level | method | long-horizon mean | short-horizon mean | other scenes: short mean | chaos floor: mean |\n|---|---|---|---|---|---|---|"
        );
        let spread = |v: Vec<f64>| {
            Spread::of(&v).map_or("—".to_string(), |s| {
                format!("{} ± {} ({}–{})", pct(s.mean), pct(s.sd), pct(s.min), pct(s.max))
            })
        };
        let mut seen: Vec<(&str, Method)> = Vec::new();
        for (_, r) in rows {
            if seen.contains(&(r.scene.as_str(), r.method)) {
                continue;
            }
            seen.push((r.scene.as_str(), r.method));
            let mine: Vec<&SuiteRow> = rows
                .iter()
                .map(|(_, x)| x)
                .filter(|x| x.scene == r.scene && x.method == r.method)
                .collect();
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} |",
                r.scene,
                r.level,
                r.method,
                spread(mine.iter().map(|x| x.own.mean).collect()),
                spread(mine.iter().map(|x| x.own.short_mean).collect()),
                spread(
                    mine.iter()
                        .filter_map(|x| x.transferred.map(|t| t.short_mean))
                        .collect()
                ),
                spread(mine.iter().map(|x| x.floor.mean).collect()),
            );
        }
    }
    // What each estimate says of itself: a fit whose guard kept its start
    // scores as that start, which the table alone does not show.
    // A note every draw of a scene and method shares is written once.
    let noted: Vec<&(usize, SuiteRow)> = rows.iter().filter(|(_, r)| !r.notes.is_empty()).collect();
    if !noted.is_empty() {
        let _ = writeln!(md, "\nEstimates:\n");
        let mut written: Vec<(&str, Method)> = Vec::new();
        for (draw, r) in noted {
            let key = (r.scene.as_str(), r.method);
            let shared = rows
                .iter()
                .filter(|(_, x)| x.scene == r.scene && x.method == r.method)
                .all(|(_, x)| x.notes == r.notes);
            if shared && written.contains(&key) {
                continue;
            }
            written.push(key);
            let at = if drawn && !shared {
                format!(" (draw {draw})")
            } else {
                String::new()
            };
            let _ = writeln!(md, "- {} {} {}{at}: {}", r.scene, r.level, r.method, r.notes);
        }
    }
    let _ = writeln!(
        md,
        "\n| method | mean over scenes{0} | worst scene{0} | short-horizon mean | other scenes / own (long) | other scenes / own (short) |\n|---|---|---|---|---|---|",
        if drawn { " and draws" } else { "" }
    );
    for &m in methods {
        let mine: Vec<&SuiteRow> = rows.iter().map(|(_, r)| r).filter(|r| r.method == m).collect();
        let n = mine.len().max(1) as f64;
        let mean = mine.iter().map(|r| r.own.mean).sum::<f64>() / n;
        let worst = mine.iter().map(|r| r.own.mean).fold(0.0, f64::max);
        let short = mine.iter().map(|r| r.own.short_mean).sum::<f64>() / n;
        let ratio = |f: fn(&HeldOut) -> f64| {
            let v: Vec<f64> = mine
                .iter()
                .filter_map(|r| r.transferred.map(|t| f(&t) / f(&r.own)))
                .collect();
            if v.is_empty() {
                "—".to_string()
            } else {
                format!(
                    "{:.2}× (worst {:.2}×)",
                    v.iter().sum::<f64>() / v.len() as f64,
                    v.iter().copied().fold(0.0, f64::max)
                )
            }
        };
        let _ = writeln!(
            md,
            "| {m} | {} | {} | {} | {} | {} |",
            pct(mean),
            pct(worst),
            pct(short),
            ratio(|h| h.mean),
            ratio(|h| h.short_mean)
        );
    }
    md
}

/// The command as it was run (`lodcloth` and its arguments), for the
/// table's caption.
fn command_line() -> String {
    let args: Vec<String> = std::env::args().skip(1).collect();
    format!("lodcloth {}", args.join(" "))
}

/// Short-horizon against long-horizon held-out error, one point per scene
/// and method.
pub(super) fn suite_chart(out: &Path, rows: &[(usize, SuiteRow)], methods: &[Method]) -> Result<()> {
    let names: Vec<String> = methods.iter().map(|m| m.name().to_string()).collect();
    let series: Vec<Series<'_>> = methods
        .iter()
        .enumerate()
        .map(|(i, &m)| Series {
            name: &names[i],
            points: rows
                .iter()
                .filter(|(_, r)| r.method == m)
                .map(|(_, r)| (100.0 * r.own.mean, 100.0 * r.own.short_mean))
                .collect(),
            markers: true,
            color: PALETTE[i % PALETTE.len()],
        })
        .collect();
    line_chart_svg(
        &out.join("short_vs_long.svg"),
        "Held-out error per scene: short horizon vs long horizon",
        "long horizon: mean error (% of O_max)",
        "short horizon: mean error (% of O_max)",
        &series,
        true,
        true,
    )?;
    info!("wrote {}", out.join("short_vs_long.svg").display());
    Ok(())
}
