//! The command-line pieces the `lodcloth` binary shares with the lab's
//! (`crates/lodcloth-lab`): progress bars, integrator names, grid scenes and
//! the point-surface model arguments.

use std::path::Path;

use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};

use crate::scene::Scene;
use crate::sim::Integrator;

/// Command-line integrator names: the config files' names, `-` allowed for `_`.
pub fn integrator_arg(name: &str) -> Result<Integrator, crate::names::UnknownName> {
    crate::names::parse_arg(name)
}

/// A progress bar of `len` steps named `what` (hidden when stderr is not a
/// terminal: callers then log their progress instead).
pub fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta} left)")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

/// A grid cloth's scene file (a mesh cloth is refused, naming the file).
pub fn grid_scene(path: &Path) -> Result<Scene> {
    let scene = Scene::load(path)?;
    anyhow::ensure!(
        scene.mesh.is_none(),
        "{}: a mesh cloth; this command runs grid cloths \
         (`lodcloth-lab generalise --scenes {} --level 40%` runs a mesh cloth's levels)",
        scene.origin,
        path.display()
    );
    Ok(scene)
}

/// A point-sampled surface from the command line: the cloud, its
/// simplification and its physics.
pub mod points {
    use std::path::PathBuf;
    use std::time::Instant;

    use anyhow::{bail, Context, Result};
    use clap::Args;
    use tracing::info;

    use super::integrator_arg;
    use crate::points::generate::extreme_point;
    use crate::points::knn::Knn;
    use crate::points::model::{PointModel, Pull, SurfaceParams};
    use crate::points::simplify::SimplifyOptions;
    use crate::points::transfer::{NormalUpdate, TransferOptions};
    use crate::points::{io, normals, PointCloud};
    use crate::sim::vec3::V3;
    use crate::sim::{Integrator, SpringCoeffs};

    /// The cloud, its simplification and its physics.
    #[derive(Args, Clone)]
    pub struct ModelArgs {
        /// Input cloud (.ply, .xyz); normals are estimated when it has none.
        #[arg(long)]
        pub input: PathBuf,
        /// Number of simulation points to keep.
        #[arg(long)]
        pub target: Option<usize>,
        /// Remove points whose one-ring diameter is below this (m).
        #[arg(long)]
        pub threshold: Option<f64>,
        /// Neighbours projected for each one-ring (10–20 in the paper).
        #[arg(long, default_value_t = 15)]
        pub k: usize,
        #[arg(long, value_parser = integrator_arg, default_value = "symplectic_euler")]
        pub integrator: Integrator,
        /// Time step (s); default 0.8 × the predicted stability limit.
        #[arg(long)]
        pub dt: Option<f64>,
        /// Areal density (kg/m²).
        #[arg(long, default_value_t = 0.3)]
        pub density: f64,
        /// Stretch spring stiffness and damping "K,C".
        #[arg(long, default_value = "50,0.05", value_parser = parse_coeffs)]
        pub stretch: SpringCoeffs,
        /// Bend spring stiffness and damping "K,C".
        #[arg(long, default_value = "5,0.005", value_parser = parse_coeffs)]
        pub bend: SpringCoeffs,
        /// Global drag (1/s).
        #[arg(long, default_value_t = 0.5)]
        pub drag: f64,
        /// Gravity "x,y,z" (m/s², z is up).
        #[arg(long, default_value = "0,0,0", value_parser = parse_v3, allow_hyphen_values = true)]
        pub gravity: V3,
        /// Pin the simulation points with z at or below this (m).
        #[arg(long, allow_hyphen_values = true)]
        pub pin_below: Option<f64>,
        /// Point to pull: "top", "bottom" or an index into the input cloud.
        #[arg(long)]
        pub pull: Option<String>,
        /// Pull target relative to the point's rest position, "dx,dy,dz" (m).
        #[arg(long, default_value = "0,0,0.3", value_parser = parse_v3, allow_hyphen_values = true)]
        pub pull_offset: V3,
        /// Pull stiffness k_r (N/m).
        #[arg(long, default_value_t = 20.0)]
        pub pull_k: f64,
        /// Release the pull at this time (s); never when absent.
        #[arg(long)]
        pub release: Option<f64>,
        /// Recompute normals by covariance (the paper) instead of the MLS gradient.
        #[arg(long)]
        pub covariance_normals: bool,
    }

    /// Comma-separated numbers.
    pub fn parse_list(s: &str) -> Result<Vec<f64>, String> {
        s.split(',')
            .map(|x| x.trim().parse::<f64>().map_err(|e| format!("`{x}`: {e}")))
            .collect()
    }

    pub fn parse_v3(s: &str) -> Result<V3, String> {
        match parse_list(s)?.as_slice() {
            &[x, y, z] if [x, y, z].iter().all(|c| c.is_finite()) => Ok([x, y, z]),
            _ => Err(format!("expected three finite numbers \"x,y,z\", got `{s}`")),
        }
    }

    pub fn parse_coeffs(s: &str) -> Result<SpringCoeffs, String> {
        match parse_list(s)?.as_slice() {
            &[k, c] => Ok(SpringCoeffs { k, c }),
            _ => Err(format!("expected \"K,C\", got `{s}`")),
        }
    }

    /// Read the input and make sure it has oriented normals.
    pub fn load(a: &ModelArgs) -> Result<PointCloud> {
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

    pub fn build(
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
        let bar = super::progress_bar(to_remove, "simplifying");
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
}
