//! The broad phase's search structure: a bounding-volume hierarchy of
//! axis-aligned boxes over a fixed set of primitives (a cloth's triangles,
//! or its edges), built once from the rest shape and refitted to new boxes
//! at every rebuild of the candidates. A cloth keeps its topology, so a
//! tree of parts that are close on the cloth stays a tree of parts that
//! are close in space however it moves; refitting costs one pass over the
//! tree, where a hashed grid is built anew and enters every box in every
//! cell it overlaps.
//!
//! The tree is stored depth first with skip links (a node's left child
//! follows it; `skip` is the node after its subtree), so a query is one
//! forward walk over contiguous memory. Leaves hold up to [`LEAF`]
//! primitives, their boxes copied into tree order at each refit.

/// An axis-aligned box: `[min x, min y, min z, max x, max y, max z]`.
pub type Aabb = [f64; 6];

/// Whether two boxes overlap (touching counts).
#[inline]
pub fn overlap(a: &Aabb, b: &Aabb) -> bool {
    a[0] <= b[3] && b[0] <= a[3] && a[1] <= b[4] && b[1] <= a[4] && a[2] <= b[5] && b[2] <= a[5]
}

/// Primitives per leaf at most.
const LEAF: usize = 4;

/// An empty box: the identity of [`union`].
pub const EMPTY: Aabb = [
    f64::INFINITY,
    f64::INFINITY,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
];

/// The smallest box holding both.
#[inline]
pub fn union(a: &Aabb, b: &Aabb) -> Aabb {
    [
        a[0].min(b[0]),
        a[1].min(b[1]),
        a[2].min(b[2]),
        a[3].max(b[3]),
        a[4].max(b[4]),
        a[5].max(b[5]),
    ]
}

/// A bounding-volume hierarchy over primitives `0..n`.
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    /// Per tree node, its box (after [`Bvh::refit`]).
    boxes: Vec<Aabb>,
    /// Per tree node, the node after its subtree.
    skip: Vec<u32>,
    /// Per tree node, its primitives `order[first..last]` (a leaf), or an
    /// empty range (an inner node, whose children are the next node and
    /// the one after the left child's subtree).
    first: Vec<u32>,
    last: Vec<u32>,
    /// The primitives in tree order, and their boxes in that order.
    order: Vec<u32>,
    leaf_boxes: Vec<Aabb>,
}

impl Bvh {
    /// The tree of primitives with these boxes (their rest shape's), split
    /// at the median of their centres along the widest side, down to
    /// leaves of [`LEAF`].
    pub fn new(boxes: &[Aabb]) -> Bvh {
        let mut tree = Bvh {
            order: (0..boxes.len() as u32).collect(),
            leaf_boxes: vec![EMPTY; boxes.len()],
            ..Bvh::default()
        };
        if !boxes.is_empty() {
            let centre = |i: u32, c: usize| boxes[i as usize][c] + boxes[i as usize][c + 3];
            let mut order = std::mem::take(&mut tree.order);
            tree.split(&mut order, 0, &centre);
            tree.order = order;
        }
        tree.refit(boxes);
        tree
    }

    /// Appends the subtree of `prims` (which start at `order[offset]`).
    fn split(&mut self, prims: &mut [u32], offset: usize, centre: &impl Fn(u32, usize) -> f64) {
        let node = self.skip.len();
        self.boxes.push(EMPTY);
        self.skip.push(0);
        if prims.len() <= LEAF {
            self.first.push(offset as u32);
            self.last.push((offset + prims.len()) as u32);
        } else {
            self.first.push(0);
            self.last.push(0);
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for &p in prims.iter() {
                for c in 0..3 {
                    lo[c] = lo[c].min(centre(p, c));
                    hi[c] = hi[c].max(centre(p, c));
                }
            }
            let axis = (0..3)
                .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
                .unwrap_or(0);
            let mid = prims.len() / 2;
            prims.select_nth_unstable_by(mid, |&a, &b| centre(a, axis).total_cmp(&centre(b, axis)));
            let (left, right) = prims.split_at_mut(mid);
            self.split(left, offset, centre);
            self.split(right, offset + mid, centre);
        }
        self.skip[node] = self.skip.len() as u32;
    }

    /// Every node's box from the primitives' `boxes` (indexed as at
    /// construction), children before parents.
    pub fn refit(&mut self, boxes: &[Aabb]) {
        for (slot, &p) in self.leaf_boxes.iter_mut().zip(&self.order) {
            *slot = boxes[p as usize];
        }
        for node in (0..self.skip.len()).rev() {
            let (first, last) = (self.first[node] as usize, self.last[node] as usize);
            self.boxes[node] = if first < last {
                self.leaf_boxes[first..last].iter().fold(EMPTY, |u, b| union(&u, b))
            } else {
                let left = node + 1;
                let right = self.skip[left] as usize;
                union(&self.boxes[left], &self.boxes[right])
            };
        }
    }

    /// Calls `visit(primitive)` once for every primitive whose box (as of
    /// the last refit) overlaps `query`.
    #[inline]
    pub fn each_overlap(&self, query: &Aabb, mut visit: impl FnMut(u32)) {
        let mut node = 0;
        let end = self.skip.len();
        while node < end {
            if !overlap(query, &self.boxes[node]) {
                node = self.skip[node] as usize;
                continue;
            }
            let (first, last) = (self.first[node] as usize, self.last[node] as usize);
            for j in first..last {
                if overlap(query, &self.leaf_boxes[j]) {
                    visit(self.order[j]);
                }
            }
            node += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every primitive whose box overlaps a query is visited exactly once,
    /// and no other, after the boxes moved far from those the tree was
    /// built on.
    #[test]
    fn every_overlap_is_visited_once_after_a_refit() {
        let mut seed = 0x9abc_def0_u64;
        let mut rand = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut random_boxes = |n: usize| -> Vec<Aabb> {
            (0..n)
                .map(|_| {
                    let c = [rand() - 0.5, rand() - 0.5, rand() - 0.5];
                    let h = [0.1 * rand(), 0.1 * rand(), 0.1 * rand()];
                    [
                        c[0] - h[0],
                        c[1] - h[1],
                        c[2] - h[2],
                        c[0] + h[0],
                        c[1] + h[1],
                        c[2] + h[2],
                    ]
                })
                .collect()
        };
        for n in [0, 1, 3, 4, 5, 17, 300] {
            let rest = random_boxes(n);
            let moved = random_boxes(n);
            let queries = random_boxes(200);
            let mut tree = Bvh::new(&rest);
            tree.refit(&moved);
            for (i, q) in queries.iter().enumerate() {
                let mut seen = vec![0u32; n];
                tree.each_overlap(q, |j| seen[j as usize] += 1);
                for (j, b) in moved.iter().enumerate() {
                    assert_eq!(seen[j], u32::from(overlap(q, b)), "{n} boxes: query {i}, box {j}");
                }
            }
        }
    }
}
