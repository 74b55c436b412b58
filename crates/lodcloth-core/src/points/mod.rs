//! Point-sampled surfaces (Su et al. 2007; `REFERENCE.md` §2) on the same
//! core as the cloth: a scanned cloud with no mesh is simplified, a
//! mass-spring surface is built on the survivors from local tangent-plane
//! Delaunay triangulations and simulated by [`crate::sim::Simulation`], and
//! the motion is carried back to every original point by moving least
//! squares.
//!
//! Pipeline, one module per stage (all pure: no I/O except [`io`], no
//! allocation in the per-step [`transfer`]):
//! - [`io`] — PLY (ASCII/binary, with or without normals) and XYZ text;
//! - [`generate`] — test shapes (sphere, hat, patch, noisy variants);
//! - [`knn`] — k-nearest-neighbour index (kiddo);
//! - [`normals`] — covariance normals and their consistent orientation;
//! - [`local`] — a point's tangent frame and Delaunay one-ring (spade);
//! - [`simplify`] — Delaunay-based simplification to a threshold or count;
//! - [`surface`] — springs (stretch and bend), masses, a ready [`crate::sim::Topology`];
//! - [`transfer`] — displacement and normals of the full cloud from the simulated points;
//! - [`model`] — the pipeline assembled; [`estimate`] — per-size stiffness fit;
//!   [`scene`] — surface scene files for the daemon's `surface` instances.

pub mod cloud;
pub mod estimate;
pub mod generate;
pub mod io;
pub mod knn;
pub mod local;
pub mod model;
pub mod normals;
pub mod scene;
pub mod simplify;
pub mod surface;
pub mod transfer;

use crate::sim::vec3::V3;

/// A point cloud: positions and, when known, unit normals.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// Point positions (m).
    pub positions: Vec<V3>,
    /// Unit normals, one per point (`None` until estimated or read).
    pub normals: Option<Vec<V3>>,
}

impl PointCloud {
    /// A cloud without normals.
    pub fn new(positions: Vec<V3>) -> PointCloud {
        PointCloud {
            positions,
            normals: None,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when the cloud has no point.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Axis-aligned bounds (min, max); zeros for an empty cloud.
    pub fn bounds(&self) -> (V3, V3) {
        if self.positions.is_empty() {
            return ([0.0; 3], [0.0; 3]);
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.positions {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        (lo, hi)
    }

    /// Length of the bounding-box diagonal.
    pub fn diagonal(&self) -> f64 {
        let (lo, hi) = self.bounds();
        crate::sim::vec3::dist(lo, hi)
    }
}

/// An `f64` with the IEEE total order, for priority queues of distances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct OrdF64(pub f64);

impl Eq for OrdF64 {}

impl PartialOrd for OrdF64 {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for OrdF64 {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}
