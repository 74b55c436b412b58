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

    /// Whether tree node `i` is a leaf.
    #[inline]
    fn leaf(&self, i: usize) -> bool {
        self.first[i] < self.last[i]
    }

    /// Tree node `i`'s two children (`i` is not a leaf).
    #[inline]
    fn children(&self, i: usize) -> [usize; 2] {
        [i + 1, self.skip[i + 1] as usize]
    }

    /// Calls `visit(a, b)` once for every primitive `a` of this tree and
    /// `b` of `other` whose boxes (as of the last refits) overlap: both
    /// trees descended together, so that a pair of far subtrees is
    /// dismissed at once. `stack` is scratch.
    pub fn each_pair(&self, other: &Bvh, stack: &mut Vec<(u32, u32)>, mut visit: impl FnMut(u32, u32)) {
        stack.clear();
        if self.skip.is_empty() || other.skip.is_empty() {
            return;
        }
        stack.push((0, 0));
        while let Some((i, j)) = stack.pop() {
            let (i, j) = (i as usize, j as usize);
            if !overlap(&self.boxes[i], &other.boxes[j]) {
                continue;
            }
            match (self.leaf(i), other.leaf(j)) {
                (true, true) => {
                    for p in self.first[i] as usize..self.last[i] as usize {
                        let bp = &self.leaf_boxes[p];
                        for q in other.first[j] as usize..other.last[j] as usize {
                            if overlap(bp, &other.leaf_boxes[q]) {
                                visit(self.order[p], other.order[q]);
                            }
                        }
                    }
                }
                // The larger subtree is split (sizes by their nodes' count).
                (false, leaf_j) if leaf_j || self.skip[i] as usize - i >= other.skip[j] as usize - j => {
                    for c in self.children(i) {
                        stack.push((c as u32, j as u32));
                    }
                }
                _ => {
                    for c in other.children(j) {
                        stack.push((i as u32, c as u32));
                    }
                }
            }
        }
    }

    /// Calls `visit(a, b)` once for every two primitives `a` ≠ `b` of this
    /// tree whose boxes overlap (as [`Bvh::each_pair`]; each unordered pair
    /// once). A task `(i, i)` is a subtree against itself.
    pub fn each_self_pair(&self, stack: &mut Vec<(u32, u32)>, mut visit: impl FnMut(u32, u32)) {
        stack.clear();
        if self.skip.is_empty() {
            return;
        }
        stack.push((0, 0));
        while let Some((i, j)) = stack.pop() {
            let (i, j) = (i as usize, j as usize);
            if i == j {
                if self.leaf(i) {
                    let (first, last) = (self.first[i] as usize, self.last[i] as usize);
                    for p in first..last {
                        for q in p + 1..last {
                            if overlap(&self.leaf_boxes[p], &self.leaf_boxes[q]) {
                                visit(self.order[p], self.order[q]);
                            }
                        }
                    }
                } else {
                    let [l, r] = self.children(i);
                    stack.extend([(l as u32, l as u32), (r as u32, r as u32), (l as u32, r as u32)]);
                }
                continue;
            }
            if !overlap(&self.boxes[i], &self.boxes[j]) {
                continue;
            }
            match (self.leaf(i), self.leaf(j)) {
                (true, true) => {
                    for p in self.first[i] as usize..self.last[i] as usize {
                        let bp = &self.leaf_boxes[p];
                        for q in self.first[j] as usize..self.last[j] as usize {
                            if overlap(bp, &self.leaf_boxes[q]) {
                                visit(self.order[p], self.order[q]);
                            }
                        }
                    }
                }
                (false, leaf_j) if leaf_j || self.skip[i] as usize - i >= self.skip[j] as usize - j => {
                    for c in self.children(i) {
                        stack.push((c as u32, j as u32));
                    }
                }
                _ => {
                    for c in self.children(j) {
                        stack.push((i as u32, c as u32));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rand_boxes(seed: &mut u64, n: usize) -> Vec<Aabb> {
        let mut rand = || {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            (*seed >> 11) as f64 / (1u64 << 53) as f64
        };
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
    }

    /// Every two primitives of two trees, or two of one tree, whose boxes
    /// overlap are visited exactly once, and no others, after a refit:
    /// against all pairs.
    #[test]
    fn every_overlapping_pair_is_visited_once() {
        let mut seed = 0x1234_5678_9abc_u64;
        let mut stack = Vec::new();
        for (n, m) in [(0, 5), (1, 1), (3, 9), (4, 4), (5, 17), (300, 200)] {
            let (rest_a, rest_b) = (rand_boxes(&mut seed, n), rand_boxes(&mut seed, m));
            let (a, b) = (rand_boxes(&mut seed, n), rand_boxes(&mut seed, m));
            let (mut ta, mut tb) = (Bvh::new(&rest_a), Bvh::new(&rest_b));
            ta.refit(&a);
            tb.refit(&b);
            let mut seen = vec![0u32; n * m];
            ta.each_pair(&tb, &mut stack, |p, q| seen[p as usize * m + q as usize] += 1);
            let mut own = vec![0u32; n * n];
            ta.each_self_pair(&mut stack, |p, q| {
                let (p, q) = (p.min(q) as usize, p.max(q) as usize);
                own[p * n + q] += 1;
            });
            for p in 0..n {
                for q in 0..m {
                    assert_eq!(seen[p * m + q], u32::from(overlap(&a[p], &b[q])), "{n}×{m}: {p}, {q}");
                }
                for q in 0..n {
                    let want = q > p && overlap(&a[p], &a[q]);
                    assert_eq!(own[p * n + q], u32::from(want), "{n}: {p}, {q} with itself");
                }
            }
        }
    }
}
