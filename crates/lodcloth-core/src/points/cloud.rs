//! How a surface level's simulated points move its whole cloud: the MLS
//! transfer from the simulated points to every cloud point, and the carry of
//! a state from one level of a cloud to another at a switch.

use std::sync::Arc;

use crate::points::model::PointModel;
use crate::points::transfer::Transfer;
use crate::sim::vec3::V3;
use crate::sim::State;

/// How a surface level's simulated points move its full cloud: which cloud
/// points are simulated, the MLS transfer, and the cloud it last produced.
#[derive(Debug, Clone)]
pub struct CloudMap {
    /// Cloud index of each simulated point.
    pub kept: Arc<Vec<u32>>,
    transfer: Transfer,
    /// The deformed cloud after the last [`CloudMap::update`].
    pub positions: Vec<V3>,
    /// Unit normals of the deformed cloud, one per point.
    pub normals: Vec<V3>,
    /// Scratch for velocity transfer at a switch.
    scratch: Vec<V3>,
}

impl CloudMap {
    /// The map of `model`'s level (cloud at rest).
    pub fn of(model: &PointModel) -> CloudMap {
        CloudMap {
            kept: Arc::new(model.kept.clone()),
            transfer: model.transfer.clone(),
            positions: model.rest.positions.clone(),
            normals: model.normals.clone(),
            scratch: vec![[0.0; 3]; model.rest.len()],
        }
    }

    /// Points in the full cloud.
    pub fn cloud_points(&self) -> usize {
        self.positions.len()
    }

    /// Move the cloud to simulated positions `pos` (SoA).
    pub fn update(&mut self, pos: &[f64]) {
        self.transfer.apply(pos, &mut self.positions, &mut self.normals);
    }

    /// The state of another level of the same cloud (`to` simulates cloud
    /// points `to.kept`) from `state` of this one: positions and velocities
    /// are carried through this level's transfer (linear in both, exact for
    /// affine motion), then read at the other level's points.
    pub fn carry(&mut self, state: &State, to: &CloudMap) -> State {
        self.update(&state.pos);
        self.transfer.interpolate(&state.vel, &mut self.scratch);
        let m = to.kept.len();
        let mut pos = vec![0.0; 3 * m];
        let mut vel = vec![0.0; 3 * m];
        for (k, &i) in to.kept.iter().enumerate() {
            for c in 0..3 {
                pos[c * m + k] = self.positions[i as usize][c];
                vel[c * m + k] = self.scratch[i as usize][c];
            }
        }
        State {
            pos,
            vel,
            time: state.time,
            step: state.step,
        }
    }
}
