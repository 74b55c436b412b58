//! `lodcloth-lab touched`: a recorded session (`lodcloth record`)
//! scored against the reference replaying its inputs — the live error the
//! daemon withholds while clients touch a cloth, computed afterwards.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use lodcloth::estimate::score_session;
use lodcloth::output::{line_chart_svg, CsvTable, Replay, Series, TrajectoryReader, PALETTE};

/// Score `recording`'s states against `scene` at `reference` (default: the
/// scene's own grid) replaying the recording's inputs of `episode`.
pub(super) fn touched_cmd(
    scene_path: &Path,
    recording: &Path,
    reference: Option<(usize, usize)>,
    dt: Option<f64>,
    episode: Option<u64>,
    out: Option<PathBuf>,
) -> Result<()> {
    let mut scene = lodcloth::args::grid_scene(scene_path)?;
    if let Some(dt) = dt {
        if !(dt.is_finite() && dt > 0.0) {
            bail!("--dt must be positive, got {dt}");
        }
        scene.params.dt = dt;
    }
    let mut reader = TrajectoryReader::open(recording)?;
    let h = *reader.header();
    if h.nx == 0 {
        bail!(
            "{}: not a grid cloth's recording (surfaces take no input)",
            recording.display()
        );
    }
    let events = reader.inputs()?;
    let replay = Replay::of(&events, episode, recording)?;
    // The frames of the replayed episode: the run of frames (time rising)
    // that holds the step of its first input.
    let first_frame = events
        .iter()
        .find(|e| e.episode == replay.episode)
        .map_or(0, |e| e.frame);
    let mut runs: Vec<Vec<(u64, f64, Vec<f64>)>> = vec![Vec::new()];
    while let Some(f) = reader.next_frame()? {
        let n = f.positions.len();
        let mut soa = vec![0.0; 3 * n];
        for (k, p) in f.positions.iter().enumerate() {
            for c in 0..3 {
                soa[c * n + k] = p[c];
            }
        }
        let current = runs.last_mut().expect("one run at least");
        if current.last().is_some_and(|(_, t, _)| f.time < *t) {
            runs.push(Vec::new());
        }
        runs.last_mut().expect("pushed").push((f.step, f.time, soa));
    }
    let run = runs
        .into_iter()
        .find(|r| r.first().is_some_and(|s| s.0 <= first_frame) && r.last().is_some_and(|s| s.0 >= first_frame))
        .with_context(|| {
            format!(
                "{}: no recorded state around the first input of episode {} (step {first_frame}): \
                 record while the cloth is touched",
                recording.display(),
                replay.episode
            )
        })?;
    let recorded: Vec<(f64, Vec<f64>)> = run.into_iter().map(|(_, t, p)| (t, p)).collect();
    let reference = reference.unwrap_or((scene.nx, scene.ny));
    let level = (h.nx as usize, h.ny as usize);
    println!(
        "{}: {} states of '{}' at {}x{}, {} inputs (episode {}); reference {}x{} replaying them",
        recording.display(),
        recorded.len(),
        replay.instance,
        level.0,
        level.1,
        replay.script.events().len(),
        replay.episode,
        reference.0,
        reference.1
    );
    let bar = lodcloth::args::progress_bar(1000, "replaying the reference");
    let scored = score_session(&scene, reference, level, &recorded, &replay.script, &mut |f| {
        bar.set_position((f.clamp(0.0, 1.0) * 1000.0) as u64)
    })
    .context("scoring the recording")?;
    bar.finish_and_clear();

    let out = out.unwrap_or_else(|| PathBuf::from("out").join(format!("touched-{}", replay.instance)));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("touched.csv");
    let mut csv = CsvTable::create(&csv_path, &["time_s", "error_pct"])?;
    for (t, e) in &scored.frames {
        csv.row(&[format!("{t:.6}"), format!("{:.6}", 100.0 * e)])?;
    }
    csv.finish()?;
    let svg = out.join("touched.svg");
    let first_input = replay.script.events().first().map_or(0.0, |e| e.0);
    let inputs: Vec<(f64, f64)> = replay.script.events().iter().map(|(t, _)| (*t, 0.0)).collect();
    line_chart_svg(
        &svg,
        &format!(
            "{} at {}x{} against the {}x{} reference under the same inputs",
            replay.instance, level.0, level.1, reference.0, reference.1
        ),
        "simulated time (s)",
        "eq. 9 error (% of O_max)",
        &[
            Series {
                name: "error of the recorded level",
                points: scored.frames.iter().map(|(t, e)| (*t, 100.0 * e)).collect(),
                markers: false,
                color: PALETTE[0],
            },
            Series {
                name: "inputs",
                points: inputs,
                markers: true,
                color: PALETTE[1],
            },
        ],
        false,
        false,
    )?;
    let r = &scored.report;
    println!(
        "from the first input (t = {first_input:.3} s) over {} states: mean {:.3} %, p95 {:.3} %, max {:.3} % \
         of O_max {:.3} m (the touched reference's); worst at t = {:.3} s",
        r.frames,
        100.0 * r.mean,
        100.0 * r.p95,
        100.0 * r.max,
        scored.o_max,
        r.worst_time
    );
    println!("wrote {} and {}", csv_path.display(), svg.display());
    Ok(())
}
