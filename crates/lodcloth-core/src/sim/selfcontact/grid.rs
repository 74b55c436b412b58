//! The broad phase: axis-aligned boxes hashed into a uniform grid of
//! cells, a box entered in every cell it overlaps (Teschner et al. 2003,
//! "Optimized spatial hashing for collision detection of deformable
//! objects"). Rebuilt from scratch whenever asked, by a counting sort into
//! buffers that only grow: a cloth's steady state allocates nothing.

/// An axis-aligned box: `[min x, min y, min z, max x, max y, max z]`.
pub type Aabb = [f64; 6];

/// Whether two boxes overlap (touching counts).
#[inline]
pub fn overlap(a: &Aabb, b: &Aabb) -> bool {
    a[0] <= b[3] && b[0] <= a[3] && a[1] <= b[4] && b[1] <= a[4] && a[2] <= b[5] && b[2] <= a[5]
}

/// A cell's integer coordinates packed into one key (21 bits each, offset
/// so that negative cells pack too; coordinates beyond ±2²⁰ cells wrap,
/// which only costs the hash more false candidates, never a missed one:
/// candidates are checked by their boxes).
#[inline]
fn key(c: [i64; 3]) -> u64 {
    const MASK: u64 = (1 << 21) - 1;
    let f = |x: i64| ((x + (1 << 20)) as u64) & MASK;
    f(c[0]) | (f(c[1]) << 21) | (f(c[2]) << 42)
}

/// `⌊x⌋` as an integer. `f64::floor` is a call into libm on a target
/// without SSE4.1, and the broad phase takes one for every box's every
/// side and every pair it reports; truncation, then one step down for a
/// negative non-integer, is the same for every |x| below 2⁶³.
#[inline(always)]
fn floor(x: f64) -> i64 {
    let t = x as i64;
    t.saturating_sub(i64::from((t as f64) > x))
}

#[inline]
fn bucket(key: u64, mask: usize) -> usize {
    // A multiplicative hash of the packed key (Knuth's constant, 64-bit).
    (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32) as usize & mask
}

/// Boxes in a hashed grid.
#[derive(Debug, Clone, Default)]
pub struct Grid {
    inv_cell: f64,
    mask: usize,
    /// Bucket b's entries are `entries[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    /// (cell key, box index), sorted by bucket.
    entries: Vec<(u64, u32)>,
    /// Per bucket, the entries placed so far while filling.
    fill: Vec<u32>,
}

impl Grid {
    /// The cell range a box overlaps.
    #[inline]
    fn range(&self, b: &Aabb) -> ([i64; 3], [i64; 3]) {
        // Written out: `[0, 1, 2].map(…)` stays a call here.
        let i = self.inv_cell;
        let lo = [floor(b[0] * i), floor(b[1] * i), floor(b[2] * i)];
        let hi = [floor(b[3] * i), floor(b[4] * i), floor(b[5] * i)];
        (lo, hi)
    }

    /// The grid of `boxes` with cubic cells `cell` metres wide.
    pub fn build(&mut self, boxes: &[Aabb], cell: f64) {
        self.inv_cell = 1.0 / cell;
        // Twice as many buckets as (cell, box) entries: a query's bucket
        // then holds little besides its own cell's boxes.
        let total: usize = boxes
            .iter()
            .map(|b| {
                let (lo, hi) = self.range(b);
                (0..3).map(|c| (hi[c] - lo[c] + 1) as usize).product::<usize>()
            })
            .sum();
        let buckets = (2 * total).next_power_of_two().max(64);
        self.mask = buckets - 1;
        self.start.clear();
        self.start.resize(buckets + 1, 0);
        // Count every (cell, box), then place them by bucket.
        for b in boxes {
            let (lo, hi) = self.range(b);
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        self.start[bucket(key([x, y, z]), self.mask) + 1] += 1;
                    }
                }
            }
        }
        for i in 0..buckets {
            self.start[i + 1] += self.start[i];
        }
        self.entries.clear();
        self.entries.resize(total, (0, 0));
        self.fill.clear();
        self.fill.extend_from_slice(&self.start[..buckets]);
        for (i, b) in boxes.iter().enumerate() {
            let (lo, hi) = self.range(b);
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        let k = key([x, y, z]);
                        let slot = &mut self.fill[bucket(k, self.mask)];
                        self.entries[*slot as usize] = (k, i as u32);
                        *slot += 1;
                    }
                }
            }
        }
    }

    /// Calls `visit(index)` once for every box of the grid that overlaps
    /// `query` (a box of another set, or of this one).
    ///
    /// A pair is reported in one cell only: the cell that holds the low
    /// corner of the two boxes' intersection.
    #[inline]
    pub fn each_overlap(&self, query: &Aabb, boxes: &[Aabb], mut visit: impl FnMut(u32)) {
        let (lo, hi) = self.range(query);
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    let cell = [x, y, z];
                    let k = key(cell);
                    let b = bucket(k, self.mask);
                    for &(ek, i) in &self.entries[self.start[b] as usize..self.start[b + 1] as usize] {
                        if ek != k {
                            continue;
                        }
                        let other = &boxes[i as usize];
                        if !overlap(query, other) {
                            continue;
                        }
                        // The intersection's low corner's cell.
                        let inv = self.inv_cell;
                        let low = [
                            floor(query[0].max(other[0]) * inv),
                            floor(query[1].max(other[1]) * inv),
                            floor(query[2].max(other[2]) * inv),
                        ];
                        if low == cell {
                            visit(i);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every overlapping pair of random boxes is visited exactly once, and
    /// no other, whatever the cell size against the boxes' sizes.
    #[test]
    fn every_overlapping_pair_is_visited_once() {
        let mut seed = 0x1234_5678_u64;
        let mut rand = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let boxes: Vec<Aabb> = (0..300)
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
            .collect();
        for cell in [0.013, 0.05, 0.4] {
            let mut grid = Grid::default();
            grid.build(&boxes, cell);
            for (i, q) in boxes.iter().enumerate() {
                let mut seen = vec![0u32; boxes.len()];
                grid.each_overlap(q, &boxes, |j| seen[j as usize] += 1);
                for (j, b) in boxes.iter().enumerate() {
                    let want = u32::from(overlap(q, b));
                    assert_eq!(seen[j], want, "cell {cell}: boxes {i} and {j}");
                }
            }
        }
    }
}
