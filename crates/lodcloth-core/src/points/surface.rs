//! The mass-spring surface on the simulation points (Su et al. 2007 §3.2):
//! each point's one-ring among its `k` nearest simulation points, sorted
//! counter-clockwise on its tangent plane; a stretching spring to every
//! one-ring neighbour and a bending spring between one-ring neighbours r and
//! r+2; node mass ρ·area(R_i)/3. The result is an ordinary
//! [`Topology`] (stretch springs are [`SpringKind::Structural`], bend
//! springs [`SpringKind::Bend`], no shear), so every integrator, the strain
//! control and the stability prediction of the cloth apply unchanged.
//!
//! Local triangulations of neighbouring points need not agree. A spring is
//! an unordered pair, kept once whichever ring proposed it; a bend pair that
//! is already a stretch spring is dropped (the pair would otherwise be
//! stiffened twice). The triangles are the union of all rings' triangles,
//! each kept once, oriented as the first ring that had it.

use std::collections::{HashMap, HashSet};

use super::knn::Knn;
use super::local::{one_ring, OneRing, RingScratch};
use crate::sim::vec3::{dist, V3};
use crate::sim::{SpringClass, SpringGroup, Topology};

/// Why a surface could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SurfaceError {
    /// Fewer than 4 points.
    #[error("a surface needs at least 4 points, got {0}")]
    TooFew(usize),
    /// Fewer than 4 neighbours per one-ring.
    #[error("k = {0} neighbours is too few for a one-ring (need at least 4)")]
    FewNeighbours(usize),
    /// Two points at the same place.
    #[error("point {index} repeats point {other}: two simulation points at the same place")]
    Duplicate {
        /// The later point.
        index: usize,
        /// The earlier point at the same place.
        other: usize,
    },
    /// A point whose one-ring has no triangle.
    #[error("point {0} has no triangle in its one-ring (isolated from the rest of the surface)")]
    Isolated(usize),
}

/// Springs, rings and masses of a point-sampled surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    /// Springs, rest shape, triangles and node areas (area(R_i)/3).
    pub topology: Topology,
    /// The one-ring of every simulation point.
    pub rings: Vec<OneRing>,
}

impl Surface {
    /// Build the surface on `points` with unit `normals`, each ring from the
    /// `k` nearest other points.
    pub fn build(points: &[V3], normals: &[V3], k: usize) -> Result<Surface, SurfaceError> {
        let n = points.len();
        if n < 4 {
            return Err(SurfaceError::TooFew(n));
        }
        if k < 4 {
            return Err(SurfaceError::FewNeighbours(k));
        }
        let knn = Knn::new(points);
        let mut found = Vec::new();
        let mut cand = Vec::new();
        let mut scratch = RingScratch::default();
        let mut rings = Vec::with_capacity(n);
        for (i, p) in points.iter().enumerate() {
            knn.nearest(*p, k + 1, &mut found);
            if let Some(&(j, d2)) = found.iter().find(|r| r.0 as usize != i) {
                if d2 == 0.0 {
                    return Err(SurfaceError::Duplicate {
                        index: i.max(j as usize),
                        other: i.min(j as usize),
                    });
                }
            }
            cand.clear();
            cand.extend(found.iter().map(|r| r.0).filter(|&j| j as usize != i));
            let ring = one_ring(points, i as u32, normals[i], &cand, &mut scratch);
            if ring.triangles(i as u32).next().is_none() {
                return Err(SurfaceError::Isolated(i));
            }
            rings.push(ring);
        }

        let key = |a: u32, b: u32| if a < b { (a, b) } else { (b, a) };
        let mut stretch = Vec::new();
        let mut seen = HashSet::new();
        for (i, r) in rings.iter().enumerate() {
            for &j in &r.ring {
                if seen.insert(key(i as u32, j)) {
                    stretch.push(key(i as u32, j));
                }
            }
        }
        let mut bend = Vec::new();
        let mut seen_bend = HashSet::new();
        for r in &rings {
            let m = r.ring.len();
            let pairs = if r.closed { m } else { m.saturating_sub(2) };
            if m < 3 {
                continue;
            }
            for a in 0..pairs {
                let (p, q) = (r.ring[a], r.ring[(a + 2) % m]);
                let pq = key(p, q);
                if p != q && !seen.contains(&pq) && seen_bend.insert(pq) {
                    bend.push(pq);
                }
            }
        }
        let rest = |pairs: &[(u32, u32)]| -> Vec<f64> {
            pairs
                .iter()
                .map(|&(a, b)| dist(points[a as usize], points[b as usize]))
                .collect()
        };
        let groups = vec![
            SpringGroup::from_pairs(SpringClass::StructuralU, &stretch, rest(&stretch)),
            SpringGroup::from_pairs(SpringClass::BendU, &bend, rest(&bend)),
        ];

        let mut triangles = Vec::new();
        let mut seen_tri = HashMap::new();
        for (i, r) in rings.iter().enumerate() {
            for t in r.triangles(i as u32) {
                let mut s = t;
                s.sort_unstable();
                seen_tri.entry(s).or_insert_with(|| {
                    triangles.push(t);
                });
            }
        }
        let topology = Topology {
            n_nodes: n,
            rest_positions: points.to_vec(),
            node_areas: rings.iter().map(|r| r.area / 3.0).collect(),
            groups,
            triangles,
            grid: None,
            mesh: None,
            bending: Default::default(),
        };
        Ok(Surface { topology, rings })
    }

    /// Node masses ρ·area(R_i)/3 for an areal density ρ (kg/m²).
    pub fn masses(&self, density: f64) -> Vec<f64> {
        self.topology.node_areas.iter().map(|a| density * a).collect()
    }
}
