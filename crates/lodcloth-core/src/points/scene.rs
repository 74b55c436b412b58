//! Surface scenes: a point cloud (a file or a generated shape) with its
//! physics, pins and pulls, read from TOML — the surface counterpart of
//! [`crate::scene::Scene`], used by the daemon's `surface` instances.
//!
//! ```toml
//! name = "sphere-pulled"
//! cloud = "sphere"            # sphere | hat | patch, or a .ply/.xyz file
//! count = 3203                # generated shapes: points
//! size = 0.5                  # generated shapes: radius or side (m)
//! gravity = [0.0, 0.0, -9.81]
//! pin_below = -0.35           # pin the simulated points with z ≤ this
//! duration = 3.0              # s; the scene loops here
//! [[pulls]]
//! point = "top"               # top | bottom | a cloud index
//! offset = [0.0, 0.0, 0.2]
//! stiffness = 20.0
//! release = 1.0
//! ```
//!
//! Every other field has the default of `lodcloth points simulate`. Loading
//! validates every value and reports each problem with its field; the cloud
//! gets oriented covariance normals when its file has none.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;

use super::generate::{extreme_point, generate, Shape};
use super::knn::Knn;
use super::model::{ModelError, PointModel, Pull, SurfaceParams};
use super::simplify::SimplifyOptions;
use super::transfer::{NormalUpdate, TransferOptions};
use super::{io, normals, PointCloud};
use crate::hash::fnv1a64;
use crate::names;
use crate::problems::Problems;
use crate::sim::{Integrator, Material, SpringCoeffs, SpringKind};

/// Why a surface scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SurfaceSceneError {
    /// The scene file, or the point-cloud file it names, could not be read
    /// (a scene file that is not UTF-8 lands here too).
    #[error("cannot read surface scene {path}: {source}")]
    Io {
        /// The unreadable file's path, as given.
        path: String,
        /// What the operating system reported.
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown or mistyped fields (the message
    /// names the line and column, and the key).
    #[error("surface scene {origin}: {message}")]
    Parse {
        /// The scene file's path, or the name the caller gave the text.
        origin: String,
        /// What is wrong and where, from the TOML parser.
        message: String,
    },
    /// The values parsed but are invalid. Checks of single fields report
    /// every problem at once; the checks that depend on the cloud (count or
    /// noise given for a file, too few points, a pull index beyond the
    /// cloud) follow them and report one problem each.
    #[error("surface scene {origin} is invalid:\n  - {}", problems.join("\n  - "))]
    Invalid {
        /// The scene file's path, or the name the caller gave the text.
        origin: String,
        /// One line per problem, each naming its field (e.g. `ring_k: …`).
        problems: Vec<String>,
    },
    /// The point-cloud file was read but is not a valid .ply or .xyz cloud.
    #[error("surface scene {origin}: {source}")]
    Cloud {
        /// The scene file's path, or the name the caller gave the text.
        origin: String,
        /// The point-cloud reader's reason.
        source: io::PointsIoError,
    },
}

/// A surface scene file exactly as parsed.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSurfaceScene {
    /// Short name of the scene, for listings and messages.
    pub name: String,
    /// Free text for listings; default empty.
    #[serde(default)]
    pub description: String,
    /// `sphere`, `hat`, `patch` or a point-cloud file (.ply, .xyz).
    pub cloud: String,
    /// Generated shapes: point count (default: 3,203 sphere, 1,600 hat, 2,500 patch).
    pub count: Option<usize>,
    /// Generated shapes: radius or side (m).
    #[serde(default = "default_size")]
    pub size: f64,
    /// Generated shapes: normal jitter as a multiple of the spacing (drops normals).
    #[serde(default)]
    pub noise: f64,
    /// Generated shapes: seed of the noise's random numbers, so a noisy
    /// shape is the same on every load; default 1 (no effect without noise).
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Neighbours projected for each one-ring (10–20 in the paper).
    #[serde(default = "default_ring_k")]
    pub ring_k: usize,
    /// Time integrator: `explicit_euler`, `symplectic_euler` (the default),
    /// `rk4` or `implicit_euler`.
    #[serde(default = "default_integrator")]
    pub integrator: String,
    /// Areal density (kg/m²).
    #[serde(default = "default_density")]
    pub density: f64,
    /// Stretch spring [K (N/m), C (N·s/m)].
    #[serde(default = "default_stretch")]
    pub stretch: [f64; 2],
    /// Bend spring [K, C].
    #[serde(default = "default_bend")]
    pub bend: [f64; 2],
    /// Global drag (1/s).
    #[serde(default = "default_drag")]
    pub drag: f64,
    /// m/s², z up.
    #[serde(default)]
    pub gravity: [f64; 3],
    /// Pin the simulated points whose z is at or below this height (m);
    /// nothing is pinned when absent.
    pub pin_below: Option<f64>,
    /// `[[pulls]]`: user springs pulling single points; default none.
    #[serde(default)]
    pub pulls: Vec<RawPull>,
    /// Recompute normals by covariance (the paper) instead of the MLS gradient.
    #[serde(default)]
    pub covariance_normals: bool,
    /// Scene length (s): the reference is recorded over it and the daemon
    /// loops at it.
    #[serde(default = "default_duration")]
    pub duration: f64,
    /// Reference frames per second (the error is measured at these instants).
    #[serde(default = "default_frame_hz")]
    pub frame_hz: f64,
}

/// A user spring pulling one point towards a world point.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPull {
    /// `top`, `bottom` or a cloud index.
    pub point: PullPoint,
    /// Target relative to the point's rest position (m).
    pub offset: [f64; 3],
    /// Spring constant k_r (N/m), finite and ≥ 0; default 20.
    #[serde(default = "default_pull_k")]
    pub stiffness: f64,
    /// Damping of the pulled point's velocity (N·s/m), finite and ≥ 0;
    /// default 0.
    #[serde(default)]
    pub damping: f64,
    /// Release time (s); held for ever when absent.
    pub release: Option<f64>,
}

/// Which point a pull holds.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum PullPoint {
    /// A point's index in the cloud; must be below the cloud's size.
    Index(usize),
    /// `top` (the point with the largest z) or `bottom` (the smallest z).
    Named(String),
}

fn default_size() -> f64 {
    0.5
}
fn default_seed() -> u64 {
    1
}
fn default_ring_k() -> usize {
    15
}
fn default_integrator() -> String {
    "symplectic_euler".into()
}
fn default_density() -> f64 {
    0.3
}
fn default_stretch() -> [f64; 2] {
    [50.0, 0.05]
}
fn default_bend() -> [f64; 2] {
    [5.0, 0.005]
}
fn default_drag() -> f64 {
    0.5
}
fn default_duration() -> f64 {
    3.0
}
fn default_frame_hz() -> f64 {
    30.0
}
fn default_pull_k() -> f64 {
    20.0
}

/// A validated surface scene with its cloud loaded (normals included).
#[derive(Debug, Clone)]
pub struct SurfaceScene {
    /// Short name of the scene (the file's `name`), for listings and messages.
    pub name: String,
    /// Free text for listings; empty when the file has none.
    pub description: String,
    /// The full point cloud, with normals (estimated by covariance and
    /// oriented when the file has none).
    pub cloud: Arc<PointCloud>,
    /// Physics; `dt` is chosen per level (`safety` × its limit, dividing the frame interval).
    pub params: SurfaceParams,
    /// Neighbours projected for each one-ring, in 6..=40 (default 15).
    pub ring_k: usize,
    /// Simulated points with z at or below this height (m) are pinned;
    /// `None` pins nothing.
    pub pin_below: Option<f64>,
    /// User springs, each on a point index of the full cloud.
    pub pulls: Vec<Pull>,
    /// How the simulated motion is carried back to every cloud point (MLS);
    /// normals by the MLS gradient, or by covariance when the file sets
    /// `covariance_normals`.
    pub transfer: TransferOptions,
    /// Scene length (s), positive: the reference is recorded over it and the
    /// daemon loops at it.
    pub duration: f64,
    /// Reference frames per second (Hz), positive; the error is measured at
    /// these instants.
    pub frame_hz: f64,
    /// FNV-1a of the scene text and the cloud file's bytes (cache keys).
    pub source_hash: u64,
}

impl SurfaceScene {
    /// Read, parse and validate a scene file; a cloud path inside it is
    /// relative to the working directory.
    pub fn load(path: &Path) -> Result<SurfaceScene, SurfaceSceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SurfaceSceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        SurfaceScene::from_toml(&text, &path.display().to_string())
    }

    /// Parse and validate scene text; `origin` names it in messages.
    pub fn from_toml(text: &str, origin: &str) -> Result<SurfaceScene, SurfaceSceneError> {
        let raw: RawSurfaceScene = toml::from_str(text).map_err(|e| SurfaceSceneError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        SurfaceScene::validate(raw, origin, fnv1a64(text.as_bytes()))
    }

    /// Check every field (all problems at once), then load or generate the cloud.
    pub fn validate(raw: RawSurfaceScene, origin: &str, text_hash: u64) -> Result<SurfaceScene, SurfaceSceneError> {
        let (p, integrator) = check_fields(&raw);
        let invalid = |problems| SurfaceSceneError::Invalid {
            origin: origin.to_string(),
            problems,
        };
        if let Err(problems) = p.finish() {
            return Err(invalid(problems));
        }
        let (mut cloud, cloud_hash) = load_cloud(&raw, origin)?;
        if cloud.len() < 4 {
            return Err(invalid(vec![format!(
                "cloud: a surface needs at least 4 points, {} has {}",
                raw.cloud,
                cloud.len()
            )]));
        }
        if cloud.normals.is_none() {
            let knn = Knn::new(&cloud.positions);
            cloud.normals = Some(normals::estimate_oriented(&cloud.positions, &knn, 12));
        }
        let mut pulls = Vec::with_capacity(raw.pulls.len());
        for (i, pull) in raw.pulls.iter().enumerate() {
            let point = match &pull.point {
                PullPoint::Index(k) if *k < cloud.len() => *k,
                PullPoint::Index(k) => {
                    return Err(invalid(vec![format!(
                        "pulls[{i}].point: {k} is beyond the cloud's {} points",
                        cloud.len()
                    )]))
                }
                PullPoint::Named(n) if n == "bottom" => extreme_point(&cloud.positions, [0.0, 0.0, -1.0]),
                PullPoint::Named(_) => extreme_point(&cloud.positions, [0.0, 0.0, 1.0]),
            };
            pulls.push(Pull {
                point,
                offset: pull.offset,
                stiffness: pull.stiffness,
                damping: pull.damping,
                release: pull.release,
            });
        }
        let coeffs = |[k, c]: [f64; 2]| SpringCoeffs { k, c };
        Ok(SurfaceScene {
            name: raw.name,
            description: raw.description,
            cloud: Arc::new(cloud),
            params: SurfaceParams {
                density: raw.density,
                stretch: coeffs(raw.stretch),
                bend: coeffs(raw.bend),
                gravity: raw.gravity,
                drag: raw.drag,
                integrator: integrator.unwrap_or(Integrator::SymplecticEuler),
                dt: None,
                safety: 0.8,
                frame_interval: Some(1.0 / raw.frame_hz),
            },
            ring_k: raw.ring_k,
            pin_below: raw.pin_below,
            pulls,
            transfer: TransferOptions {
                normals: if raw.covariance_normals {
                    NormalUpdate::Covariance { k: 10 }
                } else {
                    NormalUpdate::Gradient
                },
                ..TransferOptions::default()
            },
            duration: raw.duration,
            frame_hz: raw.frame_hz,
            source_hash: text_hash ^ cloud_hash.rotate_left(17),
        })
    }

    /// Points in the full cloud.
    pub fn points(&self) -> usize {
        self.cloud.len()
    }

    /// Reference frames over the scene's duration.
    pub fn frames(&self) -> usize {
        (self.duration * self.frame_hz).round() as usize
    }

    /// Seconds between reference frames.
    pub fn interval(&self) -> f64 {
        1.0 / self.frame_hz
    }

    /// The model simulating `points` of the cloud (all of them when
    /// `points` is the cloud size), with `integrator` and the scene's
    /// springs or `material`'s stretch and bend; its dt is `safety` × the
    /// limit of those springs, dividing the frame interval.
    pub fn model(
        &self,
        points: usize,
        integrator: Integrator,
        material: Option<&Material>,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<PointModel, ModelError> {
        let simplify = (points < self.cloud.len()).then_some(SimplifyOptions {
            k: self.ring_k,
            threshold: None,
            target: Some(points),
        });
        let (stretch, bend) = match material {
            Some(m) => (m.of_kind(SpringKind::Structural), m.of_kind(SpringKind::Bend)),
            None => (self.params.stretch, self.params.bend),
        };
        let params = SurfaceParams {
            integrator,
            stretch,
            bend,
            ..self.params
        };
        PointModel::build(
            &self.cloud,
            simplify.as_ref(),
            self.ring_k,
            &params,
            self.pin_below,
            &self.pulls,
            &self.transfer,
            progress,
        )
    }
}

/// Every field of a surface scene that can be checked without its cloud
/// (all problems at once), and its integrator if the name is known.
fn check_fields(raw: &RawSurfaceScene) -> (Problems, Option<Integrator>) {
    let mut p = Problems::new();
    for (name, v) in [
        ("density", raw.density),
        ("duration", raw.duration),
        ("frame_hz", raw.frame_hz),
        ("size", raw.size),
    ] {
        p.positive(name, v);
    }
    for (name, v) in [
        ("stretch[0] (K)", raw.stretch[0]),
        ("stretch[1] (C)", raw.stretch[1]),
        ("bend[0] (K)", raw.bend[0]),
        ("bend[1] (C)", raw.bend[1]),
        ("drag", raw.drag),
        ("noise", raw.noise),
    ] {
        p.non_negative(name, v);
    }
    for (i, g) in raw.gravity.iter().enumerate() {
        p.finite(&format!("gravity[{i}]"), *g);
    }
    if let Some(z) = raw.pin_below {
        p.finite("pin_below", z);
    }
    if !(6..=40).contains(&raw.ring_k) {
        p.push(format!(
            "ring_k: must be in 6..=40 (10–20 in the paper), got {}",
            raw.ring_k
        ));
    }
    let integrator = names::parse::<Integrator>(&raw.integrator)
        .map_err(|e| p.push(format!("integrator: {e}")))
        .ok();
    if raw.duration * raw.frame_hz < 3.0 {
        p.push(format!(
            "duration: duration × frame_hz must give at least 3 frames to measure an error, got {}",
            raw.duration * raw.frame_hz
        ));
    }
    if let Some(count) = raw.count {
        p.at_least("count", count, 4);
    }
    for (i, pull) in raw.pulls.iter().enumerate() {
        for (k, v) in pull.offset.iter().enumerate() {
            p.finite(&format!("pulls[{i}].offset[{k}]"), *v);
        }
        p.non_negative(&format!("pulls[{i}].stiffness"), pull.stiffness);
        p.non_negative(&format!("pulls[{i}].damping"), pull.damping);
        if let Some(t) = pull.release {
            p.positive(&format!("pulls[{i}].release"), t);
        }
        if let PullPoint::Named(n) = &pull.point {
            if n != "top" && n != "bottom" {
                p.push(format!("pulls[{i}].point: '{n}' is not top, bottom or a point index"));
            }
        }
    }
    (p, integrator)
}

/// The scene's cloud, generated or read from its file, and a hash of the
/// file's bytes (0 for a generated shape, whose parameters are in the text).
fn load_cloud(raw: &RawSurfaceScene, origin: &str) -> Result<(PointCloud, u64), SurfaceSceneError> {
    Ok(match Shape::from_name(&raw.cloud) {
        Some(shape) => {
            let count = raw.count.unwrap_or(match shape {
                Shape::Sphere => 3203,
                Shape::Hat => 1600,
                Shape::Patch => 2500,
            });
            (generate(shape, count, raw.size, raw.noise, raw.seed), 0)
        }
        None => {
            let path = PathBuf::from(&raw.cloud);
            if raw.count.is_some() || raw.noise != 0.0 {
                return Err(SurfaceSceneError::Invalid {
                    origin: origin.to_string(),
                    problems: vec![format!(
                        "count/noise: only for generated shapes (sphere, hat, patch), not the file {}",
                        raw.cloud
                    )],
                });
            }
            let bytes = std::fs::read(&path).map_err(|source| SurfaceSceneError::Io {
                path: path.display().to_string(),
                source,
            })?;
            let cloud = io::read(&path).map_err(|source| SurfaceSceneError::Cloud {
                origin: origin.to_string(),
                source,
            })?;
            (cloud, fnv1a64(&bytes))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bad_field_is_named() {
        let text = r#"
name = "s"
cloud = "sphere"
count = 400
density = 0
stretch = [-1.0, 0.1]
ring_k = 3
integrator = "leapfrog"
duration = 0.05
[[pulls]]
point = "middle"
offset = [0.0, 0.0, 0.1]
release = -1.0
"#;
        let e = SurfaceScene::from_toml(text, "t.toml").unwrap_err().to_string();
        for needle in [
            "density",
            "stretch[0]",
            "ring_k",
            "leapfrog",
            "frames",
            "pulls[0].point",
            "pulls[0].release",
        ] {
            assert!(e.contains(needle), "{needle} missing from: {e}");
        }
        let unknown = SurfaceScene::from_toml("name = \"s\"\ncloud = \"sphere\"\nstiffnes = 3\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(unknown.contains("stiffnes"), "{unknown}");
    }

    #[test]
    fn a_generated_scene_builds_models_of_any_size_with_the_pull_on_the_top() {
        let text =
            "name = \"s\"\ncloud = \"sphere\"\ncount = 500\n[[pulls]]\npoint = \"top\"\noffset = [0.0, 0.0, 0.1]\n";
        let scene = SurfaceScene::from_toml(text, "t.toml").unwrap();
        assert_eq!(scene.points(), 500);
        assert_eq!(scene.frames(), 90);
        let top = scene.pulls[0].point;
        assert!(scene
            .cloud
            .positions
            .iter()
            .all(|p| p[2] <= scene.cloud.positions[top][2]));
        let m = scene
            .model(120, Integrator::SymplecticEuler, None, &mut |_, _| {})
            .unwrap();
        assert_eq!(m.sim_points(), 120);
        // dt divides the frame interval.
        let per = scene.interval() / m.sim.params().dt;
        assert!((per - per.round()).abs() < 1e-9, "{per}");
        let all = scene
            .model(500, Integrator::SymplecticEuler, None, &mut |_, _| {})
            .unwrap();
        assert!(all.simplification.is_none());
    }
}
