//! `lodcloth-lab …`: the level-of-detail studies, with their files
//! (CSV, markdown, SVG charts and error maps).

use std::fs;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use tracing::info;

mod generalise;
mod readings;
mod table1;
mod touched;

use lodcloth::cache::CoefficientCache;
use lodcloth::estimate::{FitOptions, Method, Reading, RecordSpec, Reference};
use lodcloth::output::{line_chart_svg, CsvTable, Series, PALETTE};
use lodcloth::plan::{default_problem, record_reference, Estimator, GridLevel};
use lodcloth::scene::Scene;
use lodcloth::sim::Integrator;
use lodcloth_lab::experiments::generalise::TWIN_PERTURBATION;
use lodcloth_lab::experiments::lod::{lod_plan, pareto, switch_test, Horizon};

const PAPER_SCENES: [&str; 3] = [
    "config/scenes/paper-1-top-edge.toml",
    "config/scenes/paper-2-corner.toml",
    "config/scenes/paper-3-left-edge.toml",
];

/// The generalisation suite (issue 19): scenes written before any estimator
/// was tuned on them, each with its reasoning in the file.
const SUITE_SCENES: [&str; 6] = [
    "config/scenes/flag-2to1-wind.toml",
    "config/scenes/banner-1to3-gusts.toml",
    "config/scenes/tablecloth-pulled-corner.toml",
    "config/scenes/curtain-shaken.toml",
    "config/scenes/stiff-canvas-cantilever.toml",
    "config/scenes/soft-knit-drape.toml",
];

/// Table 1 of Sung 2018 (mean error %, reference 64×64): level, same, BCD, GKD.
const PAPER_TABLE1: [(usize, f64, f64, f64); 6] = [
    (60, 6.56, 4.47, 4.36),
    (56, 9.68, 5.35, 5.16),
    (52, 12.93, 6.11, 5.89),
    (48, 16.81, 6.93, 6.65),
    (44, 20.25, 7.43, 7.12),
    (40, 26.93, 11.22, 10.48),
];

/// Arguments shared by every experiment.
#[derive(clap::Args, Clone)]
pub struct Common {
    /// Scene files (default: the paper's three scenes).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<PathBuf>,
    /// Reference frames (steps of the reference run; the paper's 20,000).
    #[arg(long, default_value_t = 20_000)]
    frames: u64,
    /// Score every this many reference steps.
    #[arg(long, default_value_t = 10)]
    metric_stride: u64,
    /// Take an estimation sample every this many reference steps.
    #[arg(long, default_value_t = 40)]
    estimate_stride: u64,
    /// Steps between the positions a sample differences (1 = consecutive, the paper's).
    #[arg(long, default_value_t = 1)]
    difference_span: u64,
    /// Reference resolution, as for levels: N (along the longer side, the
    /// aspect ratio kept) or NXxNY (default: each scene's own).
    #[arg(long)]
    reference: Option<GridLevel>,
    /// Training frames of `fit` (evenly spaced) and its iteration limit.
    #[arg(long, default_value_t = 120)]
    fit_frames: usize,
    #[arg(long, default_value_t = 12)]
    fit_iterations: usize,
    /// Fraction of the run `fit` trains on (the rest is held out).
    #[arg(long, default_value_t = 0.5)]
    train_fraction: f64,
    /// How BCD and GKD read the paper's lost equations 3–8 (see
    /// `lodcloth-lab readings`).
    #[arg(long, default_value_t = Reading::DEFAULT, value_parser = parse_reading)]
    reading: Reading,
    /// Small and fast, for CI: 24×24 references, 3 s runs, short fits.
    #[arg(long)]
    quick: bool,
    /// Output directory.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Coefficient cache directory (estimates are reused across runs).
    #[arg(long, default_value = "out/cache")]
    cache: PathBuf,
    /// Do not read or write the coefficient cache.
    #[arg(long)]
    no_cache: bool,
}

impl Common {
    fn apply_quick(&mut self) {
        if self.quick {
            self.reference = Some(self.reference.unwrap_or(GridLevel::Long(24)));
            self.frames = 15_000;
            self.metric_stride = 25;
            self.estimate_stride = 50;
            self.fit_frames = 30;
            self.fit_iterations = 4;
        }
    }

    /// `--scenes` (default the paper's), grid cloths only: these
    /// experiments name levels by grid sides.
    fn scenes(&self) -> Result<Vec<Scene>> {
        let scenes = self.scenes_or(&PAPER_SCENES)?;
        if let Some(s) = scenes.iter().find(|s| s.mesh.is_some()) {
            bail!(
                "{}: a mesh cloth; this experiment runs grid cloths (`lodcloth-lab generalise --level 40%` \
                 and the drape bench take mesh cloths)",
                s.origin
            );
        }
        Ok(scenes)
    }

    /// `--scenes`, or `default` when none is given.
    fn scenes_or(&self, default: &[&str]) -> Result<Vec<Scene>> {
        let paths: Vec<PathBuf> = if self.scenes.is_empty() {
            default.iter().map(PathBuf::from).collect()
        } else {
            self.scenes.clone()
        };
        paths
            .iter()
            .map(|p| {
                let mut s = Scene::load(p).with_context(|| format!("loading scene {}", p.display()))?;
                if let (Some(level), Some(_)) = (self.reference, &s.mesh) {
                    bail!(
                        "{}: --reference {level}: a mesh cloth's reference is its file's every vertex",
                        s.origin
                    );
                }
                if let Some(level) = self.reference {
                    let (nx, ny) = level.resolve(s.width, s.height);
                    s.set_resolution(nx, ny);
                }
                Ok(s)
            })
            .collect()
    }

    fn spec(&self) -> Result<RecordSpec> {
        if self.metric_stride == 0
            || self.difference_span == 0
            || self.estimate_stride < 2 * self.difference_span
            || self.frames < 4 * self.metric_stride
        {
            bail!(
                "--metric-stride and --difference-span must be ≥ 1, --estimate-stride ≥ 2 × --difference-span, \
                 and --frames ≥ 4 metric strides"
            );
        }
        Ok(RecordSpec {
            frames: self.frames,
            metric_stride: self.metric_stride,
            estimate_stride: self.estimate_stride,
            difference_span: self.difference_span,
        })
    }

    fn fit(&self, frames: usize) -> Result<FitOptions> {
        if !(self.train_fraction > 0.0 && self.train_fraction < 1.0) {
            bail!("--train-fraction must be in (0, 1), got {}", self.train_fraction);
        }
        let end = ((frames as f64 * self.train_fraction).round() as usize).clamp(1, frames - 1);
        Ok(FitOptions {
            train: Some(0..end),
            max_frames: self.fit_frames,
            max_iterations: self.fit_iterations,
            reading: self.reading,
            ..FitOptions::default()
        })
    }

    fn estimator(&self) -> Result<Estimator> {
        let cache = if self.no_cache {
            None
        } else {
            Some(
                CoefficientCache::open(&self.cache)
                    .with_context(|| format!("opening the coefficient cache {}", self.cache.display()))?,
            )
        };
        Ok(Estimator {
            cache,
            tag: format!(
                "f{}m{}e{}s{}",
                self.frames, self.metric_stride, self.estimate_stride, self.difference_span
            ),
        })
    }

    fn out(&self, default: &str) -> Result<PathBuf> {
        let dir = self.out.clone().unwrap_or_else(|| PathBuf::from(default));
        fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(dir)
    }
}

#[derive(Subcommand)]
pub enum Experiment {
    /// The paper's Table 1 for our scenes: every level and method, with CSV,
    /// markdown, an error-vs-reduction chart and worst-frame error maps.
    Table1 {
        #[command(flatten)]
        common: Common,
        /// Coarse levels: N (N nodes along the longer side, the cloth's
        /// aspect ratio kept) or NXxNY, e.g. `48,40` or `40x24,30x18`.
        #[arg(long, value_delimiter = ',')]
        levels: Vec<GridLevel>,
    },
    /// Speed against accuracy for (level, method, integrator, dt), with the
    /// Pareto front marked.
    Pareto {
        #[command(flatten)]
        common: Common,
        /// Levels, as for `table1`.
        #[arg(long, value_delimiter = ',')]
        levels: Vec<GridLevel>,
        /// Methods compared.
        #[arg(long, value_delimiter = ',', default_values_t = vec!["same".to_string(), "lsq".to_string(), "fit".to_string()])]
        methods: Vec<String>,
        /// dt as fractions of each integrator's predicted limit (implicit
        /// Euler: of 4× the symplectic limit).
        #[arg(long, value_delimiter = ',', default_values_t = vec![0.25, 0.5, 0.8])]
        dt_fractions: Vec<f64>,
        /// Implicit Euler's and XPBD's own dt fractions (of 4× the
        /// symplectic limit; may exceed 1, up to the metric frame interval);
        /// default: --dt-fractions.
        #[arg(long, value_delimiter = ',')]
        implicit_fractions: Vec<f64>,
        /// Integrators compared.
        #[arg(long, value_delimiter = ',', value_parser = lodcloth::args::integrator_arg,
              default_values_t = vec![Integrator::SymplecticEuler, Integrator::Rk4, Integrator::ImplicitEuler, Integrator::Xpbd])]
        integrators: Vec<Integrator>,
    },
    /// The coarsest level whose fitted model stays within --max-error on
    /// held-out frames.
    LodPlan {
        #[command(flatten)]
        common: Common,
        /// Largest acceptable mean error, in percent.
        #[arg(long)]
        max_error: f64,
        /// The error bounded: `long` (one run from rest, Sung eq. 9) or
        /// `short` (restarted from the reference every 0.25 s).
        #[arg(long, default_value = "long", value_parser = ["long", "short"])]
        horizon: String,
        /// Levels tried, as for `table1` (those not coarser than the reference are skipped).
        #[arg(long, value_delimiter = ',')]
        levels: Vec<GridLevel>,
    },
    /// Every estimator over the paper's scenes and the generalisation
    /// suite (default --scenes): trained on the first part of each run,
    /// scored on the rest (held-out time) and carried to the scenes it did
    /// not see (held-out scenes), long and short horizon.
    Generalise {
        #[command(flatten)]
        common: Common,
        /// Level, as for `table1` (default 40; with --quick 16).
        #[arg(long)]
        level: Option<GridLevel>,
        /// Methods compared.
        #[arg(long, value_delimiter = ',', default_values_t = ["same", "bcd", "gkd", "fit"].map(String::from).to_vec())]
        methods: Vec<String>,
        /// Relative change of the chaos floor's twins' coefficients (a
        /// larger one, e.g. 1e-3, shows where the drift saturates).
        #[arg(long, default_value_t = TWIN_PERTURBATION)]
        floor_perturbation: f64,
        /// Multiply every estimate's bend class (K and C) by this before
        /// it is scored: what a bending factor costs held out.
        #[arg(long, default_value_t = 1.0, value_parser = parse_factor)]
        bend_scale: f64,
        /// The bend class's damping factor, when it differs from
        /// --bend-scale.
        #[arg(long, value_parser = parse_factor)]
        bend_damping_scale: Option<f64>,
        /// Stiffen each level's bending modes FIRST..END or FIRST.. (softest first,
        /// every pin held) to the reference's eigenvalues, paired by
        /// order, before estimating and scoring: a mesh cloth's level made
        /// as stiff as its reference where it is softer, leaving its
        /// softest modes alone (`lodcloth_lab::modal`).
        #[arg(long, value_parser = lodcloth_lab::experiments::generalise::parse_band)]
        modal: Option<std::ops::Range<usize>>,
        /// Settle every restart of the short horizon by one backward-Euler
        /// step of this many seconds from rest at the transferred shape
        /// (`lodcloth_core::lod::settle`): what the level cannot hold of
        /// the reference's shape relaxes before the window runs.
        #[arg(long, value_parser = parse_factor)]
        settle: Option<f64>,
        /// Record every scene's reference this many times, its stiffnesses
        /// × (1 + d · --floor-perturbation) for d = 0, +1, −1, +2, …, and
        /// score every method on each: on a chaotic scene one recording is
        /// one draw of its outcome, and a level's held-out error is judged
        /// by the mean over the draws (with their spread).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
        reference_draws: u32,
    },
    /// The paper's BCD and GKD under every reading of its lost equations
    /// 3–8, with per-node masses over its levels, scored against the trend
    /// of its Table 1 (same > BCD > GKD, and by how much).
    Readings {
        #[command(flatten)]
        common: Common,
        /// Levels, as for `table1` (default: the paper's 60…40).
        #[arg(long, value_delimiter = ',')]
        levels: Vec<GridLevel>,
        /// Readings compared (default: all).
        #[arg(long, value_delimiter = ',', value_parser = parse_reading)]
        readings: Vec<Reading>,
    },
    /// A recorded session (`lodcloth record --out`, with its inputs) scored
    /// against the reference replaying the same inputs: the level's eq. 9
    /// error while clients touched it (CSV and chart).
    Touched {
        /// The instance's scene file.
        #[arg(long)]
        scene: PathBuf,
        /// The recording (.lct).
        #[arg(long)]
        recording: PathBuf,
        /// Reference grid (default: the scene's own).
        #[arg(long)]
        reference: Option<GridLevel>,
        /// The reference's dt (default: the scene's).
        #[arg(long)]
        dt: Option<f64>,
        /// The recording's episode (default: the first with inputs).
        #[arg(long)]
        episode: Option<u64>,
        /// Output directory (default: out/touched-<instance>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Switch reference ↔ a coarse level mid-run and measure the jump.
    SwitchTest {
        #[command(flatten)]
        common: Common,
        /// Coarse level, as for `table1`.
        #[arg(long, default_value_t = GridLevel::Long(40))]
        level: GridLevel,
        /// Method giving the coarse coefficients.
        #[arg(long, default_value = "fit")]
        method: String,
        /// Switch time (s) and the window scored after it (s).
        #[arg(long, default_value_t = 1.75)]
        at: f64,
        #[arg(long, default_value_t = 0.5)]
        window: f64,
    },
}

pub fn run(experiment: Experiment) -> Result<()> {
    match experiment {
        Experiment::Table1 { mut common, levels } => {
            common.apply_quick();
            let levels = if !levels.is_empty() {
                levels
            } else if common.quick {
                longs(&[16, 12])
            } else {
                longs(&[60, 56, 52, 48, 44, 40, 32, 24, 16])
            };
            table1::table1(&common, &levels)
        }
        Experiment::Pareto {
            mut common,
            levels,
            methods,
            dt_fractions,
            implicit_fractions,
            integrators,
        } => {
            common.apply_quick();
            let levels = if !levels.is_empty() {
                levels
            } else if common.quick {
                longs(&[24, 16, 12])
            } else {
                longs(&[64, 48, 40, 32, 24])
            };
            let implicit = if implicit_fractions.is_empty() {
                &dt_fractions
            } else {
                &implicit_fractions
            };
            pareto_cmd(
                &common,
                &levels,
                &parse_methods(&methods)?,
                &integrators,
                &dt_fractions,
                implicit,
            )
        }
        Experiment::LodPlan {
            mut common,
            max_error,
            horizon,
            levels,
        } => {
            common.apply_quick();
            if !(max_error > 0.0) {
                bail!("--max-error must be a positive percentage, got {max_error}");
            }
            let levels = if levels.is_empty() {
                longs(&[8, 12, 16, 24, 32, 40, 44, 48, 52, 56, 60])
            } else {
                levels
            };
            let horizon = if horizon == "short" {
                Horizon::Short { window: SHORT_WINDOW }
            } else {
                Horizon::Long
            };
            plan_cmd(&common, max_error / 100.0, horizon, &levels)
        }
        Experiment::Generalise {
            mut common,
            level,
            methods,
            floor_perturbation,
            bend_scale,
            bend_damping_scale,
            modal,
            settle,
            reference_draws,
        } => {
            common.apply_quick();
            let level = level.unwrap_or(GridLevel::Long(if common.quick { 16 } else { 40 }));
            let bend = (bend_scale, bend_damping_scale.unwrap_or(bend_scale));
            generalise::generalise_cmd(
                &common,
                level,
                &parse_methods(&methods)?,
                floor_perturbation,
                bend,
                modal,
                settle,
                reference_draws as usize,
            )
        }
        Experiment::Readings {
            mut common,
            levels,
            readings,
        } => {
            common.apply_quick();
            let levels = if !levels.is_empty() {
                levels
            } else if common.quick {
                longs(&[16, 12])
            } else {
                longs(&[60, 56, 52, 48, 44, 40])
            };
            let readings = if readings.is_empty() {
                Reading::ALL.to_vec()
            } else {
                readings
            };
            readings::readings_cmd(&common, &levels, &readings)
        }
        Experiment::Touched {
            scene,
            recording,
            reference,
            dt,
            episode,
            out,
        } => {
            let reference = match reference {
                None => None,
                Some(l) => {
                    let s = lodcloth::scene::Scene::load(&scene)?;
                    anyhow::ensure!(
                        s.mesh.is_none(),
                        "{}: a mesh cloth; `touched` runs grid cloths",
                        s.origin
                    );
                    let (nx, ny) = l.resolve(s.width, s.height);
                    Some((nx, ny))
                }
            };
            touched::touched_cmd(&scene, &recording, reference, dt, episode, out)
        }
        Experiment::SwitchTest {
            mut common,
            level,
            method,
            at,
            window,
        } => {
            common.apply_quick();
            let method = Method::from_name(&method).with_context(|| format!("--method: unknown method {method:?}"))?;
            switch_cmd(&common, level, method, at, window)
        }
    }
}

/// A factor on a coefficient: finite and positive.
fn parse_factor(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        Ok(v) => Err(format!("a factor must be finite and positive, got {v}")),
        Err(e) => Err(format!("{s:?} is not a number: {e}")),
    }
}

fn parse_reading(name: &str) -> Result<Reading, lodcloth::names::UnknownName> {
    lodcloth::names::parse_arg(name)
}

fn parse_methods(names: &[String]) -> Result<Vec<Method>> {
    names
        .iter()
        .map(|m| Method::from_name(m).with_context(|| format!("--methods: unknown method {m:?}")))
        .collect()
}

/// Window of the short-horizon measure (s): the level restarts from the
/// reference's state this often (0.25 s, as issue 19 proposes: a quarter of
/// the pull's swing, long enough for a coarse level's own dynamics to show).
const SHORT_WINDOW: f64 = 0.25;

/// Default level chains: N nodes along each scene's longer side, so every
/// level keeps the cloth's aspect ratio.
fn longs(sides: &[usize]) -> Vec<GridLevel> {
    sides.iter().map(|&n| GridLevel::Long(n)).collect()
}

fn log_line(line: String) {
    info!("{line}");
}

fn reference_for(scene: &Scene, spec: RecordSpec) -> Result<(Arc<Reference>, f64)> {
    let t = Instant::now();
    let (reference, cost) = record_reference(scene, spec, &mut log_line)?;
    info!(
        "{}: reference {} recorded in {:.1} s ({:.2} wall s per simulated s, {} MB held, O_max {:.3} m)",
        scene.name,
        scene.reference_level(),
        t.elapsed().as_secs_f64(),
        cost,
        reference.memory_bytes() / 1_000_000,
        reference.o_max
    );
    Ok((reference, cost))
}

/// The CSV columns of a model's coefficients, and their cells.
const COEFFICIENT_HEADER: [&str; 10] = [
    "k_structural_u",
    "k_structural_v",
    "k_shear",
    "k_bend_u",
    "k_bend_v",
    "c_structural_u",
    "c_structural_v",
    "c_shear",
    "c_bend_u",
    "c_bend_v",
];

fn coefficient_cells(material: &lodcloth::sim::Material) -> Vec<String> {
    let m = material.springs;
    m.iter()
        .map(|s| s.k.to_string())
        .chain(m.iter().map(|s| s.c.to_string()))
        .collect()
}

/// `before`, the coefficient columns, `after`: one CSV header.
fn header_around<'a>(before: &[&'a str], after: &[&'a str]) -> Vec<&'a str> {
    [before, &COEFFICIENT_HEADER[..], after].concat()
}

/// `before`, a model's coefficient cells, `after`: one CSV row.
fn row_around(before: Vec<String>, material: &lodcloth::sim::Material, after: Vec<String>) -> Vec<String> {
    [before, coefficient_cells(material), after].concat()
}

fn pareto_cmd(
    common: &Common,
    levels: &[GridLevel],
    methods: &[Method],
    integrators: &[Integrator],
    fractions: &[f64],
    implicit_fractions: &[f64],
) -> Result<()> {
    let out = common.out("out/pareto")?;
    let spec = common.spec()?;
    let scene = common.scenes()?.into_iter().next().context("no scene")?;
    let (reference, _) = reference_for(&scene, spec)?;
    let frames = reference.frames.len();
    let points = pareto(
        &scene,
        &reference,
        levels,
        methods,
        integrators,
        fractions,
        implicit_fractions,
        &common.fit(frames)?,
        &common.estimator()?,
        &mut log_line,
    )?;
    let mut csv = CsvTable::create(
        &out.join("pareto.csv"),
        &[
            "level",
            "method",
            "integrator",
            "dt",
            "dt_over_limit",
            "cost_s_per_s",
            "mean_error",
            "on_front",
        ],
    )?;
    for p in &points {
        csv.row(&[
            format!("{}x{}", p.nx, p.ny),
            p.method.to_string(),
            p.integrator.name().to_string(),
            format!("{:e}", p.dt),
            format!("{:.3}", p.dt_ratio),
            format!("{:.5}", p.cost),
            format!("{:.6}", p.mean_error),
            p.on_front.to_string(),
        ])?;
    }
    csv.finish()?;
    // One series per (method, integrator): which integrator a point is
    // matters as much as which coefficients.
    let pairs: Vec<(Method, Integrator)> = methods
        .iter()
        .flat_map(|&m| integrators.iter().map(move |&i| (m, i)))
        .collect();
    let names: Vec<String> = pairs
        .iter()
        .map(|(m, i)| format!("{} {}", m.name(), i.name()))
        .collect();
    let mut series: Vec<Series<'_>> = pairs
        .iter()
        .enumerate()
        .map(|(k, &(m, i))| Series {
            name: &names[k],
            points: points
                .iter()
                .filter(|p| p.method == m && p.integrator == i)
                .map(|p| (p.cost, 100.0 * p.mean_error))
                .collect(),
            markers: true,
            color: PALETTE[k % PALETTE.len()],
        })
        .collect();
    let mut front: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.on_front)
        .map(|p| (p.cost, 100.0 * p.mean_error))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    series.push(Series {
        name: "Pareto front",
        points: front,
        markers: false,
        color: PALETTE[5],
    });
    line_chart_svg(
        &out.join("pareto.svg"),
        &format!("{}: wall time per simulated second vs mean error", scene.name),
        "wall s per simulated s",
        "mean error (% of O_max)",
        &series,
        true,
        true,
    )?;
    info!("wrote {}", out.join("pareto.svg").display());
    Ok(())
}

fn plan_cmd(common: &Common, max_error: f64, horizon: Horizon, levels: &[GridLevel]) -> Result<()> {
    let out = common.out("out/lod-plan")?;
    let estimator = common.estimator()?;
    let spec = common.spec()?;
    let mut csv = CsvTable::create(
        &out.join("lod-plan.csv"),
        &header_around(&["scene", "level", "dt", "held_out_mean", "accepted"], &[]),
    )?;
    for scene in common.scenes()? {
        let (reference, _) = reference_for(&scene, spec)?;
        let fit = common.fit(reference.frames.len())?;
        let steps = lod_plan(
            &scene,
            &reference,
            levels,
            max_error,
            horizon,
            &fit,
            &estimator,
            &mut log_line,
        )?;
        match steps.iter().find(|s| s.accepted) {
            Some(s) => println!(
                "{}: {}×{} (held-out error {:.2}% ≤ {:.2}%), coefficients {:?}",
                scene.name,
                s.nx,
                s.ny,
                100.0 * s.held_out_mean,
                100.0 * max_error,
                s.material
            ),
            None => println!(
                "{}: no coarser level stays within {:.2}%; keep the reference {}×{}",
                scene.name,
                100.0 * max_error,
                scene.nx,
                scene.ny
            ),
        }
        for s in &steps {
            let before = vec![
                scene.name.clone(),
                format!("{}x{}", s.nx, s.ny),
                format!("{:e}", s.dt),
                format!("{:.6}", s.held_out_mean),
                s.accepted.to_string(),
            ];
            csv.row(&row_around(before, &s.material, Vec::new()))?;
        }
    }
    csv.finish()?;
    Ok(())
}

fn switch_cmd(common: &Common, level: GridLevel, method: Method, at: f64, window: f64) -> Result<()> {
    let out = common.out("out/switch-test")?;
    let spec = common.spec()?;
    let mut csv = CsvTable::create(
        &out.join("switch-test.csv"),
        &[
            "scene",
            "level",
            "method",
            "switch_time",
            "position_jump_m",
            "kinetic_jump",
            "error_transfer",
            "error_never_switched",
            "error_zero_velocity",
            "back_kinetic_jump",
            "back_error",
        ],
    )?;
    for scene in common.scenes()? {
        let (reference, _) = reference_for(&scene, spec)?;
        let interval = reference.dt * reference.spec.metric_stride as f64;
        let at_frame = (at / interval).round() as usize;
        let window_frames = ((window / interval).round() as usize).max(1);
        let (nx, ny) = level.resolve(scene.width, scene.height);
        let problem = default_problem(&scene, &reference, (nx, ny))?;
        let fit = common.fit(reference.frames.len())?;
        let material = common.estimator()?.estimate(&problem, method, &fit)?.material;
        let r = switch_test(&problem, material, at_frame, window_frames)?;
        println!(
            "{}: {}×{}↔{nx}×{ny} ({method}) at t = {:.3} s: position jump {:.2e} m, KE jump {:.2}%, \
             error over the next {window} s: transfer {:.2}%, never switched {:.2}%, zeroed velocities {:.2}%; \
             back to fine: KE jump {:.2}%, error {:.2}%",
            scene.name,
            scene.nx,
            scene.ny,
            r.switch_time,
            r.position_jump,
            100.0 * r.kinetic_jump,
            100.0 * r.error_transfer,
            100.0 * r.error_never_switched,
            100.0 * r.error_zero_velocity,
            100.0 * r.back_kinetic_jump,
            100.0 * r.back_error
        );
        csv.row(&[
            scene.name.clone(),
            format!("{nx}x{ny}"),
            method.to_string(),
            format!("{:.4}", r.switch_time),
            format!("{:e}", r.position_jump),
            format!("{:.6}", r.kinetic_jump),
            format!("{:.6}", r.error_transfer),
            format!("{:.6}", r.error_never_switched),
            format!("{:.6}", r.error_zero_velocity),
            format!("{:.6}", r.back_kinetic_jump),
            format!("{:.6}", r.back_error),
        ])?;
    }
    csv.finish()?;
    Ok(())
}
