//! A point-sampled surface ready to step: the cloud (with oriented normals),
//! its simplification, the mass-spring surface on the survivors as an
//! ordinary [`Simulation`], and the transfer back to every original point.

use std::sync::Arc;

use super::simplify::{simplify, Simplification, SimplifyError, SimplifyOptions};
use super::surface::{Surface, SurfaceError};
use super::transfer::{Transfer, TransferError, TransferOptions};
use super::PointCloud;
use crate::sim::vec3::{add, dist, V3};
use crate::sim::{
    CgSettings, Integrator, Loads, Material, Pin, PinPath, Profile, SimError, SimParams, Simulation, SpringCoeffs,
    StabilityCheck, State, StepReport, Tether,
};

/// Physical and numerical settings of a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceParams {
    /// Areal density ρ (kg/m²): node mass is ρ·area(R_i)/3.
    pub density: f64,
    /// Stretch springs (to one-ring neighbours).
    pub stretch: SpringCoeffs,
    /// Bend springs (between one-ring neighbours r and r+2).
    pub bend: SpringCoeffs,
    /// Gravitational acceleration (m/s²).
    pub gravity: V3,
    /// Global drag rate (1/s).
    pub drag: f64,
    /// The integrator.
    pub integrator: Integrator,
    /// Fixed time step; `None` takes `safety` × the predicted stability limit.
    pub dt: Option<f64>,
    /// Fraction of the stability limit used when `dt` is `None`.
    pub safety: f64,
    /// When `dt` is `None` and this is set, the chosen dt also divides this
    /// interval exactly (so runs at different resolutions share frame times).
    pub frame_interval: Option<f64>,
}

impl Default for SurfaceParams {
    fn default() -> Self {
        SurfaceParams {
            density: 0.3,
            stretch: SpringCoeffs { k: 50.0, c: 0.05 },
            bend: SpringCoeffs { k: 5.0, c: 0.005 },
            gravity: [0.0; 3],
            drag: 0.5,
            integrator: Integrator::SymplecticEuler,
            dt: None,
            safety: 0.8,
            frame_interval: None,
        }
    }
}

/// A user spring pulling one point of the cloud towards a world point
/// (Su et al.'s `k_r (r0 − s_i)`), acting on the nearest simulation point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pull {
    /// Index of the pulled point in the original cloud.
    pub point: usize,
    /// Target = the point's rest position + `offset` (m).
    pub offset: V3,
    /// k_r (N/m).
    pub stiffness: f64,
    /// Damping of the pulled node's velocity (N·s/m).
    pub damping: f64,
    /// Release time (s): the pull acts on [0, release). `None`: never released.
    pub release: Option<f64>,
}

/// What went wrong building a surface model.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The cloud has no normals.
    #[error("the point cloud has no normals (estimate them first)")]
    NoNormals,
    /// Simplification failed.
    #[error("simplification: {0}")]
    Simplify(#[from] SimplifyError),
    /// The springs on tangent planes could not be built.
    #[error("springs: {0}")]
    Surface(#[from] SurfaceError),
    /// The simulation refused its parameters.
    #[error("simulation: {0}")]
    Sim(#[from] SimError),
    /// The MLS transfer could not be built.
    #[error("transfer: {0}")]
    Transfer(#[from] TransferError),
    /// A pull names a point beyond the cloud.
    #[error("pull on point {point}: the cloud has {points} points")]
    PullPoint {
        /// The point index given.
        point: usize,
        /// Points in the cloud.
        points: usize,
    },
    /// A parameter out of its range.
    #[error("surface parameter {name} = {value} is invalid: {reason}")]
    Param {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        reason: &'static str,
    },
}

/// A simplified, simulated point cloud.
#[derive(Debug, Clone)]
pub struct PointModel {
    /// The original cloud at rest (with normals).
    pub rest: PointCloud,
    /// Indices of the simulation points in the original cloud.
    pub kept: Vec<u32>,
    /// Simplification statistics (`None` when every point is simulated).
    pub simplification: Option<Simplification>,
    /// The springs on the simulation points' tangent planes.
    pub surface: Arc<Surface>,
    /// The simulation of the kept points.
    pub sim: Simulation,
    /// How the simulated points move the full cloud (MLS).
    pub transfer: Transfer,
    /// The deformed full cloud after the last [`PointModel::update_cloud`].
    pub positions: Vec<V3>,
    /// Unit normals of the deformed full cloud.
    pub normals: Vec<V3>,
}

impl PointModel {
    /// Build a model of `cloud` (which must have normals). `simplify_with`
    /// `None` simulates every point. `ring_k` neighbours build each
    /// simulation point's one-ring; `pin_below` pins the simulation points
    /// whose z is at or below it.
    pub fn build(
        cloud: &PointCloud,
        simplify_with: Option<&SimplifyOptions>,
        ring_k: usize,
        params: &SurfaceParams,
        pin_below: Option<f64>,
        pulls: &[Pull],
        transfer: &TransferOptions,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<PointModel, ModelError> {
        let normals = cloud.normals.as_ref().ok_or(ModelError::NoNormals)?;
        check_params(params)?;
        let (kept, simplification) = match simplify_with {
            Some(options) => {
                let s = simplify(&cloud.positions, normals, options, progress)?;
                (s.kept.clone(), Some(s))
            }
            None => ((0..cloud.len() as u32).collect(), None),
        };
        let sim_points: Vec<V3> = kept.iter().map(|&i| cloud.positions[i as usize]).collect();
        let sim_normals: Vec<V3> = kept.iter().map(|&i| normals[i as usize]).collect();
        let surface = Surface::build(&sim_points, &sim_normals, ring_k)?;
        let topology = Arc::new(surface.topology.clone());
        let masses = surface.masses(params.density);

        let pins: Vec<Pin> = match pin_below {
            Some(z) => (0..sim_points.len())
                .filter(|&k| sim_points[k][2] <= z)
                .map(|k| Pin {
                    node: k as u32,
                    anchor: sim_points[k],
                    path: PinPath::Fixed,
                })
                .collect(),
            None => Vec::new(),
        };
        let mut tethers = Vec::with_capacity(pulls.len());
        for p in pulls {
            if p.point >= cloud.len() {
                return Err(ModelError::PullPoint {
                    point: p.point,
                    points: cloud.len(),
                });
            }
            let at = cloud.positions[p.point];
            let node = (0..sim_points.len())
                .min_by(|&a, &b| dist(sim_points[a], at).total_cmp(&dist(sim_points[b], at)))
                .expect("a surface has points");
            tethers.push(Tether {
                node: node as u32,
                target: add(sim_points[node], p.offset),
                stiffness: p.stiffness,
                damping: p.damping,
                profile: match p.release {
                    Some(t) => Profile::Pulse {
                        start: 0.0,
                        duration: t,
                    },
                    None => Profile::Constant,
                },
            });
        }
        let loads = Loads {
            pins,
            tethers,
            ..Loads::default()
        };
        let mut sim_params = SimParams {
            dt: params.dt.unwrap_or(1e-4),
            integrator: params.integrator,
            material: Material::isotropic([params.stretch, SpringCoeffs { k: 0.0, c: 0.0 }, params.bend]),
            gravity: params.gravity,
            drag: params.drag,
            stiffness_adjustment: None,
            strain_limit: None,
            cg: CgSettings::default(),
            self_contact: None,
        };
        let state = State::at_rest(&topology);
        if params.dt.is_none() {
            let probe = Simulation::new(
                topology.clone(),
                masses.clone(),
                sim_params,
                loads.clone(),
                state.clone(),
                StabilityCheck::Force,
            )?;
            let limit = probe.dt_limit();
            let dt = if limit.is_finite() { params.safety * limit } else { 1e-3 };
            sim_params.dt = match params.frame_interval {
                Some(every) => every / (every / dt).ceil().max(1.0),
                None => dt,
            };
        }
        let sim = Simulation::new(topology, masses, sim_params, loads, state, StabilityCheck::Enforce)?;
        let transfer = Transfer::new(&cloud.positions, normals, &sim_points, transfer)?;
        Ok(PointModel {
            rest: cloud.clone(),
            kept,
            simplification,
            surface: Arc::new(surface),
            sim,
            transfer,
            positions: cloud.positions.clone(),
            normals: normals.clone(),
        })
    }

    /// One simulation step (the full cloud is not updated).
    pub fn step(&mut self) -> StepReport {
        self.sim.step()
    }

    /// Move the full cloud to the current simulation state.
    pub fn update_cloud(&mut self) {
        let pos = &self.sim.state().pos;
        self.transfer.apply(pos, &mut self.positions, &mut self.normals);
    }

    /// The deformed full cloud (after [`PointModel::update_cloud`]).
    pub fn cloud(&self) -> PointCloud {
        PointCloud {
            positions: self.positions.clone(),
            normals: Some(self.normals.clone()),
        }
    }

    /// Number of simulation points.
    pub fn sim_points(&self) -> usize {
        self.kept.len()
    }
}

fn check_params(p: &SurfaceParams) -> Result<(), ModelError> {
    let bad = |name, value, reason| Err(ModelError::Param { name, value, reason });
    if !(p.density > 0.0 && p.density.is_finite()) {
        return bad("density", p.density, "must be positive (zero mass cannot be simulated)");
    }
    for (name, v) in [
        ("stretch.k", p.stretch.k),
        ("stretch.c", p.stretch.c),
        ("bend.k", p.bend.k),
        ("bend.c", p.bend.c),
        ("drag", p.drag),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            return bad(name, v, "must be finite and ≥ 0");
        }
    }
    if let Some(f) = p.frame_interval {
        if !(f > 0.0 && f.is_finite()) {
            return bad("frame_interval", f, "must be positive");
        }
    }
    if !(p.safety > 0.0 && p.safety <= 1.0) {
        return bad(
            "safety",
            p.safety,
            "must be in (0, 1]: a fraction of the stability limit",
        );
    }
    Ok(())
}
