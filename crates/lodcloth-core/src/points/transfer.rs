//! Displacement transfer from the simulation points to every original point
//! (Su et al. 2007 §3.4): moving least squares on each original point's
//! tangent plane with Gaussian weights, its value at the point being the
//! point's displacement; normals are then recomputed.
//!
//! Two departures from the paper, both to make the transfer exact where it
//! can be:
//! - The fit is linear in the tangent coordinates *and* the height above the
//!   tangent plane, `u = a0 + a1 x̄ + a2 ȳ + a3 z̄`. On a curved surface the
//!   neighbours sit off the plane, so the paper's 2-D fit is not exact for a
//!   rotation; this one reproduces every affine motion (rigid ones included)
//!   exactly. When the neighbours are coplanar (a flat patch) the z̄ column
//!   vanishes and the pseudo-inverse drops it, leaving the paper's fit.
//! - The weight is the paper's `exp(−r²/h²)` shifted to reach zero at the
//!   support radius, so the transferred field is continuous as neighbours
//!   enter and leave the support.
//!
//! Everything that depends only on the rest shape — neighbours, weights,
//! the normal-matrix inverse — is folded at construction into three weights
//! per (point, neighbour): value, ∂/∂x̄ and ∂/∂ȳ. A step is then a sparse
//! product with no allocation.

use nalgebra::{Matrix4, Vector4};

use super::knn::Knn;
use super::local::Frame;
use super::normals::covariance_normal;
use crate::sim::vec3::{add, cross, dot, normalize, scale, sub, V3};

/// How the normals of the deformed cloud are recomputed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NormalUpdate {
    /// From the MLS fit's tangent derivatives: `n ∝ (t1 + ∂u/∂x̄) × (t2 + ∂u/∂ȳ)`.
    /// Exact for affine motions and as cheap as the transfer itself.
    Gradient,
    /// The paper's covariance analysis of the `k` nearest original points
    /// (neighbours fixed at rest), signed to agree with the previous normal.
    Covariance {
        /// Nearest original points in each covariance.
        k: usize,
    },
}

/// Transfer settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransferOptions {
    /// The support radius is `support` × the distance to the `neighbours`-th
    /// nearest simulation point; the Gaussian width h is half the radius.
    pub neighbours: usize,
    /// The support radius's factor (≥ 1; see `neighbours`).
    pub support: f64,
    /// How the deformed cloud's normals are computed.
    pub normals: NormalUpdate,
}

impl Default for TransferOptions {
    fn default() -> Self {
        TransferOptions {
            neighbours: 6,
            support: 1.4,
            normals: NormalUpdate::Gradient,
        }
    }
}

/// Why a transfer could not be set up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TransferError {
    /// Fewer than 3 simulation points.
    #[error("transfer needs at least 3 simulation points, got {0}")]
    TooFew(usize),
    /// Not one normal per point.
    #[error("{normals} normals for {points} points")]
    Normals {
        /// Normals given.
        normals: usize,
        /// Points in the cloud.
        points: usize,
    },
    /// An option out of its range.
    #[error("transfer option {name} = {value} is invalid: {reason}")]
    Option {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        reason: &'static str,
    },
}

/// The precomputed transfer from a set of simulation points to a cloud.
#[derive(Debug, Clone)]
pub struct Transfer {
    n_sim: usize,
    rest: Vec<V3>,
    sim_rest: Vec<V3>,
    t1: Vec<V3>,
    t2: Vec<V3>,
    offsets: Vec<u32>,
    nbr: Vec<u32>,
    /// Per entry: weight of the neighbour's displacement in the value, ∂/∂x̄, ∂/∂ȳ.
    coef: Vec<[f64; 3]>,
    normal_update: NormalUpdate,
    /// Covariance neighbours (CSR over the original points), when used.
    cov_offsets: Vec<u32>,
    cov_nbr: Vec<u32>,
    /// Displacement of each simulation point this step.
    disp: Vec<V3>,
}

impl Transfer {
    /// Set up the transfer to the original points `rest` (unit `normals`)
    /// from simulation points whose rest positions are `sim_rest`.
    pub fn new(
        rest: &[V3],
        normals: &[V3],
        sim_rest: &[V3],
        options: &TransferOptions,
    ) -> Result<Transfer, TransferError> {
        if sim_rest.len() < 3 {
            return Err(TransferError::TooFew(sim_rest.len()));
        }
        if normals.len() != rest.len() {
            return Err(TransferError::Normals {
                normals: normals.len(),
                points: rest.len(),
            });
        }
        if options.neighbours < 3 {
            return Err(TransferError::Option {
                name: "neighbours",
                value: options.neighbours as f64,
                reason: "at least 3 points are needed for a linear fit",
            });
        }
        if !(options.support >= 1.0 && options.support.is_finite()) {
            return Err(TransferError::Option {
                name: "support",
                value: options.support,
                reason: "the support must reach the chosen neighbours (≥ 1)",
            });
        }
        let knn = Knn::new(sim_rest);
        let mut found = Vec::new();
        let mut offsets = Vec::with_capacity(rest.len() + 1);
        offsets.push(0u32);
        let mut nbr = Vec::new();
        let mut coef = Vec::new();
        let (mut t1s, mut t2s) = (Vec::with_capacity(rest.len()), Vec::with_capacity(rest.len()));
        let mut q = Vec::new();
        for (p, n) in rest.iter().zip(normals) {
            let frame = Frame::new(*p, *n);
            t1s.push(frame.t1);
            t2s.push(frame.t2);
            knn.nearest(*p, options.neighbours, &mut found);
            let dk = found.last().map_or(0.0, |r| r.1.sqrt());
            let radius = options.support * dk;
            if radius > 0.0 {
                knn.within(*p, radius, &mut found);
            } else {
                // The point coincides with its neighbours: copy the nearest.
                found.truncate(1);
            }
            let h = 0.5 * radius;
            let floor = (-(radius * radius) / (h * h)).exp();
            let mut normal = Matrix4::zeros();
            q.clear();
            for &(j, d2) in &found {
                let w = if h > 0.0 { (-d2 / (h * h)).exp() - floor } else { 1.0 };
                let l = frame.local(sim_rest[j as usize]);
                let s = if h > 0.0 { 1.0 / h } else { 0.0 };
                let v = Vector4::new(1.0, l[0] * s, l[1] * s, l[2] * s);
                normal += w * v * v.transpose();
                q.push((j, w, v));
            }
            let inv = normal
                .svd(true, true)
                .pseudo_inverse(1e-9 * normal.norm())
                .unwrap_or_else(|_| Matrix4::zeros());
            let s = if h > 0.0 { 1.0 / h } else { 0.0 };
            for &(j, w, v) in &q {
                let a = inv * v * w;
                if w > 0.0 {
                    nbr.push(j);
                    coef.push([a[0], a[1] * s, a[2] * s]);
                }
            }
            offsets.push(nbr.len() as u32);
        }
        let (mut cov_offsets, mut cov_nbr) = (Vec::new(), Vec::new());
        if let NormalUpdate::Covariance { k } = options.normals {
            let all = Knn::new(rest);
            cov_offsets.push(0u32);
            for p in rest {
                all.nearest(*p, k.max(3), &mut found);
                cov_nbr.extend(found.iter().map(|r| r.0));
                cov_offsets.push(cov_nbr.len() as u32);
            }
        }
        Ok(Transfer {
            n_sim: sim_rest.len(),
            rest: rest.to_vec(),
            sim_rest: sim_rest.to_vec(),
            t1: t1s,
            t2: t2s,
            offsets,
            nbr,
            coef,
            normal_update: options.normals,
            cov_offsets,
            cov_nbr,
            disp: vec![[0.0; 3]; sim_rest.len()],
        })
    }

    /// Number of original points.
    pub fn len(&self) -> usize {
        self.rest.len()
    }

    /// True when there is no original point.
    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }

    /// Mean number of simulation points each original point reads.
    pub fn mean_neighbours(&self) -> f64 {
        self.nbr.len() as f64 / self.rest.len().max(1) as f64
    }

    /// Positions and normals of the original points for simulation points
    /// at `sim_pos` (structure of arrays, `[x0.., y0.., z0..]`, as in
    /// [`crate::sim::State`]). `normals` holds the previous normals on entry
    /// (used only to sign covariance normals).
    ///
    /// # Panics
    /// When the slices do not match the sizes the transfer was built for.
    pub fn apply(&mut self, sim_pos: &[f64], positions: &mut [V3], normals: &mut [V3]) {
        let m = self.n_sim;
        assert_eq!(sim_pos.len(), 3 * m, "simulation positions");
        assert_eq!(positions.len(), self.rest.len(), "output positions");
        assert_eq!(normals.len(), self.rest.len(), "output normals");
        for (j, d) in self.disp.iter_mut().enumerate() {
            let r = self.sim_rest[j];
            *d = [sim_pos[j] - r[0], sim_pos[m + j] - r[1], sim_pos[2 * m + j] - r[2]];
        }
        let gradient = self.normal_update == NormalUpdate::Gradient;
        for i in 0..self.rest.len() {
            let (a, b) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
            let (mut u, mut ux, mut uy) = ([0.0; 3], [0.0; 3], [0.0; 3]);
            for e in a..b {
                let d = self.disp[self.nbr[e] as usize];
                let [c0, cx, cy] = self.coef[e];
                for c in 0..3 {
                    u[c] += c0 * d[c];
                    ux[c] += cx * d[c];
                    uy[c] += cy * d[c];
                }
            }
            positions[i] = add(self.rest[i], u);
            if gradient {
                let n = cross(add(self.t1[i], ux), add(self.t2[i], uy));
                if let Some(n) = normalize(n) {
                    normals[i] = n;
                }
            }
        }
        if let NormalUpdate::Covariance { .. } = self.normal_update {
            for i in 0..self.rest.len() {
                let (a, b) = (self.cov_offsets[i] as usize, self.cov_offsets[i + 1] as usize);
                if let Some(n) = covariance_normal(positions, self.cov_nbr[a..b].iter().copied()) {
                    normals[i] = if dot(n, normals[i]) < 0.0 { scale(n, -1.0) } else { n };
                }
            }
        }
    }

    /// The MLS value at every original point of a field known at the
    /// simulation points that is zero at rest: a displacement or a velocity
    /// (`sim_values` SoA, as in [`crate::sim::State`]). Linear in the field
    /// and exact for affine ones, so velocities follow positions through a
    /// level switch.
    ///
    /// # Panics
    /// When the slices do not match the sizes the transfer was built for.
    pub fn interpolate(&self, sim_values: &[f64], out: &mut [V3]) {
        let m = self.n_sim;
        assert_eq!(sim_values.len(), 3 * m, "simulation values");
        assert_eq!(out.len(), self.rest.len(), "output values");
        for (i, o) in out.iter_mut().enumerate() {
            let mut u = [0.0; 3];
            for e in self.offsets[i] as usize..self.offsets[i + 1] as usize {
                let j = self.nbr[e] as usize;
                let c0 = self.coef[e][0];
                for (c, uc) in u.iter_mut().enumerate() {
                    *uc += c0 * sim_values[c * m + j];
                }
            }
            *o = u;
        }
    }

    /// The displacement of original point `i` alone (for tests and probes).
    pub fn displacement_of(&self, i: usize, sim_pos: &[f64]) -> V3 {
        let m = self.n_sim;
        let mut u = [0.0; 3];
        for e in self.offsets[i] as usize..self.offsets[i + 1] as usize {
            let j = self.nbr[e] as usize;
            let d = sub([sim_pos[j], sim_pos[m + j], sim_pos[2 * m + j]], self.sim_rest[j]);
            for c in 0..3 {
                u[c] += self.coef[e][0] * d[c];
            }
        }
        u
    }
}
