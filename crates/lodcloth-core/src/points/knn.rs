//! k-nearest-neighbour and radius queries over a fixed set of points, on a
//! kiddo k-d tree. Results are `(index, squared distance)`, nearest first.

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::sim::vec3::V3;

/// A static spatial index over points (indices are positions in the slice
/// it was built from).
pub struct Knn {
    tree: Option<ImmutableKdTree<f64, 3>>,
    len: usize,
}

impl std::fmt::Debug for Knn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Knn").field("len", &self.len).finish()
    }
}

impl Knn {
    /// Index `points` (which must be finite).
    pub fn new(points: &[V3]) -> Knn {
        let tree = if points.is_empty() {
            None
        } else {
            Some(ImmutableKdTree::new_from_slice(points).expect("finite points index"))
        };
        Knn {
            tree,
            len: points.len(),
        }
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when no point is indexed.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The `k` nearest indexed points to `p` (fewer when the index is
    /// smaller), nearest first, replacing the contents of `out`.
    pub fn nearest(&self, p: V3, k: usize, out: &mut Vec<(u32, f64)>) {
        out.clear();
        let (Some(tree), Some(k)) = (&self.tree, NonZero::new(k.min(self.len))) else {
            return;
        };
        let found = tree.query(&p).nearest_n::<SquaredEuclidean<f64>>(k).execute();
        out.extend(found.into_iter().map(|r| (r.item, r.distance)));
    }

    /// Every indexed point within `radius` of `p`, nearest first, replacing
    /// the contents of `out`.
    pub fn within(&self, p: V3, radius: f64, out: &mut Vec<(u32, f64)>) {
        out.clear();
        let Some(tree) = &self.tree else {
            return;
        };
        let found = tree
            .query(&p)
            .within::<SquaredEuclidean<f64>>(radius * radius)
            .execute();
        out.extend(found.into_iter().map(|r| (r.item, r.distance)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_and_within_agree_with_brute_force() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let pts: Vec<V3> = (0..500).map(|_| [rnd(), rnd(), rnd()]).collect();
        let knn = Knn::new(&pts);
        let mut out = Vec::new();
        for q in [[0.5, 0.5, 0.5], [0.0, 1.0, 0.2], [1.5, -0.2, 0.3]] {
            let mut brute: Vec<(u32, f64)> = pts
                .iter()
                .enumerate()
                .map(|(i, p)| (i as u32, crate::sim::vec3::dist(*p, q).powi(2)))
                .collect();
            brute.sort_by(|a, b| a.1.total_cmp(&b.1));
            knn.nearest(q, 10, &mut out);
            assert_eq!(
                out.iter().map(|r| r.0).collect::<Vec<_>>(),
                brute[..10].iter().map(|r| r.0).collect::<Vec<_>>()
            );
            knn.within(q, 0.2, &mut out);
            let inside = brute.iter().filter(|r| r.1 <= 0.04).count();
            assert_eq!(out.len(), inside);
        }
        knn.nearest([0.0; 3], 1000, &mut out);
        assert_eq!(out.len(), 500);
        Knn::new(&[]).nearest([0.0; 3], 3, &mut out);
        assert!(out.is_empty());
    }
}
