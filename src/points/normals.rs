//! Normals of an unstructured cloud: the eigenvector of the smallest
//! eigenvalue of each point's k-nearest-neighbour covariance (Hoppe et al.
//! 1992, as in Su et al. 2007), then oriented consistently by propagating
//! along a minimum spanning tree of the neighbour graph whose edge cost is
//! `1 − |n_i · n_j|` (nearly parallel normals first).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use nalgebra::{Matrix3, SymmetricEigen};

use super::knn::Knn;
use super::OrdF64;
use crate::sim::vec3::{dot, scale, sub, V3};

/// Unit normal of the points `ids` (their covariance's smallest
/// eigenvector), with an arbitrary sign. `None` when fewer than 3 points.
pub fn covariance_normal(points: &[V3], ids: impl Iterator<Item = u32> + Clone) -> Option<V3> {
    let mut mean = [0.0; 3];
    let mut count = 0usize;
    for i in ids.clone() {
        let p = points[i as usize];
        for c in 0..3 {
            mean[c] += p[c];
        }
        count += 1;
    }
    if count < 3 {
        return None;
    }
    let mean = scale(mean, 1.0 / count as f64);
    let mut cov = Matrix3::zeros();
    for i in ids {
        let d = sub(points[i as usize], mean);
        for r in 0..3 {
            for c in 0..3 {
                cov[(r, c)] += d[r] * d[c];
            }
        }
    }
    smallest_eigenvector(cov)
}

/// Unit eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix.
pub fn smallest_eigenvector(m: Matrix3<f64>) -> Option<V3> {
    let eig = SymmetricEigen::new(m);
    let k = eig.eigenvalues.imin();
    let v = eig.eigenvectors.column(k);
    let n = [v[0], v[1], v[2]];
    crate::sim::vec3::normalize(n)
}

/// Unoriented normals of every point from its `k` nearest neighbours
/// (itself included). A point whose neighbourhood is degenerate (all
/// neighbours on one line) gets the normal of the nearest point that has one.
pub fn estimate(points: &[V3], knn: &Knn, k: usize) -> Vec<V3> {
    let mut out = vec![[f64::NAN; 3]; points.len()];
    let mut nb = Vec::new();
    for (i, p) in points.iter().enumerate() {
        knn.nearest(*p, k.max(3), &mut nb);
        if let Some(n) = covariance_normal(points, nb.iter().map(|r| r.0)) {
            out[i] = n;
        }
    }
    // Degenerate neighbourhoods borrow from the nearest valid point.
    for i in 0..points.len() {
        if out[i][0].is_nan() {
            knn.nearest(points[i], points.len().min(64), &mut nb);
            out[i] = nb
                .iter()
                .map(|r| out[r.0 as usize])
                .find(|n| !n[0].is_nan())
                .unwrap_or([0.0, 0.0, 1.0]);
        }
    }
    out
}

/// Flip normals so that neighbours agree, component by component of the
/// `k`-nearest-neighbour graph. Each component is seeded at the point
/// farthest from its centroid, whose normal is made to point away from the
/// centroid (outwards on closed and cap-like shapes; on a flat component,
/// where that is undefined, towards the positive side of the normal's
/// largest coordinate).
pub fn orient(points: &[V3], knn: &Knn, k: usize, normals: &mut [V3]) {
    let n = points.len();
    // Symmetric neighbour graph.
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut nb = Vec::new();
    for (i, p) in points.iter().enumerate() {
        knn.nearest(*p, k + 1, &mut nb);
        for &(j, _) in &nb {
            if j as usize != i {
                adj[i].push(j);
                adj[j as usize].push(i as u32);
            }
        }
    }
    for a in &mut adj {
        a.sort_unstable();
        a.dedup();
    }
    let mut component = vec![u32::MAX; n];
    let mut done = vec![false; n];
    let mut members = Vec::new();
    let mut stack = Vec::new();
    let mut heap = BinaryHeap::new();
    for root in 0..n {
        if component[root] != u32::MAX {
            continue;
        }
        // Collect the component.
        members.clear();
        stack.push(root as u32);
        component[root] = root as u32;
        while let Some(i) = stack.pop() {
            members.push(i);
            for &j in &adj[i as usize] {
                if component[j as usize] == u32::MAX {
                    component[j as usize] = root as u32;
                    stack.push(j);
                }
            }
        }
        let mut c = [0.0; 3];
        for &i in &members {
            for d in 0..3 {
                c[d] += points[i as usize][d] / members.len() as f64;
            }
        }
        let seed = *members
            .iter()
            .max_by(|&&a, &&b| {
                let da = dot(sub(points[a as usize], c), sub(points[a as usize], c));
                let db = dot(sub(points[b as usize], c), sub(points[b as usize], c));
                da.total_cmp(&db)
            })
            .expect("a component has a point");
        let s = seed as usize;
        let out = sub(points[s], c);
        let along = dot(normals[s], out);
        let flip = if along.abs() > 1e-6 * dot(out, out).sqrt() {
            along < 0.0
        } else {
            let m = normals[s];
            let big = (0..3).max_by(|&a, &b| m[a].abs().total_cmp(&m[b].abs())).unwrap_or(2);
            m[big] < 0.0
        };
        if flip {
            normals[s] = scale(normals[s], -1.0);
        }
        // Prim's algorithm from the seed, flipping each new point to agree
        // with the tree neighbour it is reached from.
        done[s] = true;
        for &j in &adj[s] {
            heap.push((
                Reverse(OrdF64(1.0 - dot(normals[s], normals[j as usize]).abs())),
                s as u32,
                j,
            ));
        }
        while let Some((_, from, to)) = heap.pop() {
            let t = to as usize;
            if done[t] {
                continue;
            }
            done[t] = true;
            if dot(normals[from as usize], normals[t]) < 0.0 {
                normals[t] = scale(normals[t], -1.0);
            }
            for &j in &adj[t] {
                if !done[j as usize] {
                    heap.push((Reverse(OrdF64(1.0 - dot(normals[t], normals[j as usize]).abs())), to, j));
                }
            }
        }
    }
}

/// Estimated and oriented normals (see [`estimate`] and [`orient`]).
pub fn estimate_oriented(points: &[V3], knn: &Knn, k: usize) -> Vec<V3> {
    let mut normals = estimate(points, knn, k);
    orient(points, knn, k, &mut normals);
    normals
}
