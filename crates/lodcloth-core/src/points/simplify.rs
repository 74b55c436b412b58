//! Delaunay-based simplification (Su et al. 2007 §3.1): every point gets the
//! one-ring of its `k` nearest surviving neighbours on its tangent plane;
//! the point whose ring R_i has the smallest diameter d_i is removed and the
//! rings that used it are rebuilt; this repeats until the target count is
//! reached or every d_i is at least the threshold.
//!
//! With a threshold we also keep a promise the paper implies but does not
//! enforce: every original point stays within the threshold of a survivor.
//! A removal that would break it (the points the candidate covers have no
//! other survivor that close) is refused and the candidate is kept.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::knn::Knn;
use super::local::{one_ring, RingScratch};
use super::OrdF64;
use crate::sim::vec3::{dist, V3};

/// How far to simplify. At least one of `threshold` and `target` must be set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimplifyOptions {
    /// Neighbours projected for each one-ring (the paper uses 10–20).
    pub k: usize,
    /// Remove points whose ring diameter is below this (m).
    pub threshold: Option<f64>,
    /// Stop when this many points remain.
    pub target: Option<usize>,
}

impl Default for SimplifyOptions {
    fn default() -> Self {
        SimplifyOptions {
            k: 15,
            threshold: None,
            target: None,
        }
    }
}

/// Why simplification options were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimplifyError {
    /// Neither a threshold nor a target count.
    #[error("simplification needs a threshold, a target count, or both")]
    NoStop,
    /// Fewer than 4 neighbours per one-ring.
    #[error("k = {0} neighbours is too few for a one-ring (need at least 4)")]
    FewNeighbours(usize),
    /// A threshold that is not positive and finite.
    #[error("threshold must be positive and finite, got {0}")]
    Threshold(f64),
    /// A target count outside 4..=points.
    #[error("target count {target} must be between 4 and the cloud's {points} points")]
    Target {
        /// The target given.
        target: usize,
        /// Points in the cloud.
        points: usize,
    },
    /// Not one normal per point.
    #[error("{normals} normals for {points} points")]
    Normals {
        /// Normals given.
        normals: usize,
        /// Points in the cloud.
        points: usize,
    },
}

/// Result of a simplification.
#[derive(Debug, Clone, PartialEq)]
pub struct Simplification {
    /// Indices of the surviving points (the simulation points), ascending.
    pub kept: Vec<u32>,
    /// For every original point, the survivor that covers it: its nearest
    /// survivor when its last coverer was removed (survivors only vanish, so
    /// the truly nearest one is at most this far).
    pub owner: Vec<u32>,
    /// Largest distance from an original point to its owner (m): every
    /// point lies within this of a simulation point.
    pub coverage: f64,
    /// Smallest ring diameter among the survivors when it stopped (m).
    pub min_diameter: f64,
    /// Removals refused to keep every point within the threshold of a survivor.
    pub refused: usize,
}

/// Simplify `points` with unit `normals`. `progress(removed, to_remove)` is
/// called now and then (to_remove is an estimate when only a threshold is set).
pub fn simplify(
    points: &[V3],
    normals: &[V3],
    options: &SimplifyOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Simplification, SimplifyError> {
    let n = points.len();
    if options.threshold.is_none() && options.target.is_none() {
        return Err(SimplifyError::NoStop);
    }
    if options.k < 4 {
        return Err(SimplifyError::FewNeighbours(options.k));
    }
    if let Some(t) = options.threshold {
        if !(t > 0.0 && t.is_finite()) {
            return Err(SimplifyError::Threshold(t));
        }
    }
    if let Some(target) = options.target {
        if target < 4 || target > n {
            return Err(SimplifyError::Target { target, points: n });
        }
    }
    if normals.len() != n {
        return Err(SimplifyError::Normals {
            normals: normals.len(),
            points: n,
        });
    }
    let target = options.target.unwrap_or(4);
    let mut s = State::new(points, options.k);
    let mut scratch = RingScratch::default();
    let mut cand = Vec::new();
    for i in 0..n {
        s.refresh(i as u32, normals, &mut cand, &mut scratch);
    }
    let to_remove = n - target;
    let mut refused = 0;
    let mut removed = 0;
    let mut min_diameter = f64::INFINITY;
    while s.alive_count > target {
        let Some((Reverse(OrdF64(d)), i, version)) = s.heap.pop() else {
            break;
        };
        let iu = i as usize;
        if !s.alive[iu] || version != s.version[iu] || s.locked[iu] {
            continue;
        }
        if options.threshold.is_some_and(|t| d >= t) {
            min_diameter = d;
            break;
        }
        // Who would cover the points `i` covers once it is gone?
        s.alive[iu] = false;
        s.alive_count -= 1;
        let covered = std::mem::take(&mut s.covers[iu]);
        let mut moves = Vec::with_capacity(covered.len());
        let mut ok = true;
        for &p in &covered {
            let (q, dq) = s.nearest_alive(points[p as usize]);
            if options.threshold.is_some_and(|t| dq > t) {
                ok = false;
                break;
            }
            moves.push((p, q));
        }
        if !ok {
            s.covers[iu] = covered;
            s.alive[iu] = true;
            s.alive_count += 1;
            s.locked[iu] = true;
            refused += 1;
            continue;
        }
        for (p, q) in moves {
            s.owner[p as usize] = q;
            s.covers[q as usize].push(p);
        }
        // Rebuild the rings that used `i`.
        let users = std::mem::take(&mut s.users[iu]);
        for u in users {
            if s.alive[u as usize] && s.cands[u as usize].contains(&i) {
                s.refresh(u, normals, &mut cand, &mut scratch);
            }
        }
        // Only now: a refused removal must find `i` in the index again.
        s.maybe_rebuild();
        removed += 1;
        if removed % 256 == 0 {
            progress(removed, to_remove);
        }
    }
    progress(removed, to_remove);
    let kept: Vec<u32> = (0..n as u32).filter(|&i| s.alive[i as usize]).collect();
    if min_diameter.is_infinite() {
        min_diameter = kept
            .iter()
            .map(|&i| s.diameter[i as usize])
            .fold(f64::INFINITY, f64::min);
    }
    let coverage = (0..n)
        .map(|p| dist(points[p], points[s.owner[p] as usize]))
        .fold(0.0, f64::max);
    Ok(Simplification {
        kept,
        owner: s.owner,
        coverage,
        min_diameter,
        refused,
    })
}

/// Mutable bookkeeping of a simplification.
struct State<'a> {
    points: &'a [V3],
    k: usize,
    alive: Vec<bool>,
    alive_count: usize,
    locked: Vec<bool>,
    /// Ring candidates of each point (its k nearest survivors when built).
    cands: Vec<Vec<u32>>,
    /// Points whose candidates include this one (may hold stale entries).
    users: Vec<Vec<u32>>,
    diameter: Vec<f64>,
    version: Vec<u32>,
    heap: BinaryHeap<(Reverse<OrdF64>, u32, u32)>,
    /// Nearest survivor of every original point, and its inverse.
    owner: Vec<u32>,
    covers: Vec<Vec<u32>>,
    /// Index over a superset of the survivors; `ids` maps its entries back.
    index: Knn,
    ids: Vec<u32>,
    found: Vec<(u32, f64)>,
}

impl<'a> State<'a> {
    fn new(points: &'a [V3], k: usize) -> State<'a> {
        let n = points.len();
        State {
            points,
            k,
            alive: vec![true; n],
            alive_count: n,
            locked: vec![false; n],
            cands: vec![Vec::new(); n],
            users: vec![Vec::new(); n],
            diameter: vec![0.0; n],
            version: vec![0; n],
            heap: BinaryHeap::with_capacity(2 * n),
            owner: (0..n as u32).collect(),
            covers: (0..n as u32).map(|i| vec![i]).collect(),
            index: Knn::new(points),
            ids: (0..n as u32).collect(),
            found: Vec::new(),
        }
    }

    /// Re-index the survivors once the index holds twice as many points,
    /// so queries do not wade through the removed ones.
    fn maybe_rebuild(&mut self) {
        if self.alive_count * 2 < self.ids.len() && self.alive_count >= 8 {
            self.ids = (0..self.alive.len() as u32)
                .filter(|&i| self.alive[i as usize])
                .collect();
            let pts: Vec<V3> = self.ids.iter().map(|&i| self.points[i as usize]).collect();
            self.index = Knn::new(&pts);
        }
    }

    /// Up to `want` nearest survivors of `p` (excluding `skip`), into `out`.
    fn nearest_survivors(&mut self, p: V3, want: usize, skip: u32, out: &mut Vec<u32>) {
        out.clear();
        let mut ask = want + 1;
        loop {
            self.index.nearest(p, ask, &mut self.found);
            out.clear();
            for &(e, _) in &self.found {
                let id = self.ids[e as usize];
                if id != skip && self.alive[id as usize] {
                    out.push(id);
                    if out.len() == want {
                        return;
                    }
                }
            }
            if ask >= self.index.len() {
                return;
            }
            ask = (ask * 2).min(self.index.len());
        }
    }

    /// Nearest survivor of `p` and its distance.
    fn nearest_alive(&mut self, p: V3) -> (u32, f64) {
        let mut one = Vec::with_capacity(1);
        self.nearest_survivors(p, 1, u32::MAX, &mut one);
        let q = one[0];
        (q, dist(p, self.points[q as usize]))
    }

    /// Rebuild point `i`'s ring and queue it with its new diameter.
    fn refresh(&mut self, i: u32, normals: &[V3], cand: &mut Vec<u32>, scratch: &mut RingScratch) {
        let iu = i as usize;
        self.nearest_survivors(self.points[iu], self.k, i, cand);
        let ring = one_ring(self.points, i, normals[iu], cand, scratch);
        let (users, alive, cands) = (&mut self.users, &self.alive, &self.cands);
        for &c in cand.iter() {
            let list = &mut users[c as usize];
            list.push(i);
            // Drop stale entries now and then so the lists stay O(k).
            if list.len() > 4 * self.k {
                list.sort_unstable();
                list.dedup();
                list.retain(|&u| u == i || (alive[u as usize] && cands[u as usize].contains(&c)));
            }
        }
        self.cands[iu].clear();
        self.cands[iu].extend_from_slice(cand);
        // A point whose ring is degenerate (fewer than two neighbours) is
        // never removed first: it would leave a hole.
        let d = if ring.ring.len() >= 2 {
            ring.diameter
        } else {
            f64::INFINITY
        };
        self.diameter[iu] = d;
        self.version[iu] += 1;
        self.heap.push((Reverse(OrdF64(d)), i, self.version[iu]));
    }
}
