//! Linear bending stencils: a bending energy with a continuum limit.
//!
//! A bend spring across an edge shortens by about L·θ²/8 when its two
//! triangles fold by θ, so its energy is quartic in the fold and the folding
//! energy per area of a mesh goes as K·κ⁴·h⁴: it has no continuum limit, and
//! two meshes of one fabric fold differently (the lab's NOTEBOOK.md, "What the Cusick
//! error is made of"). A plate's bending energy is quadratic in curvature,
//! `½·D·∫ (κ₁ + κ₂)² − 2(1 − ν)·κ₁κ₂ dA` with the bending rigidity D (N·m).
//!
//! Here the energy is `½·D·Σ_s |Σ_i w_si·x_i|²`: each stencil `s` is a
//! fixed linear combination of a few nodes' positions that vanishes on the
//! flat rest shape and on every affine map of it (Σ w = 0, Σ w·X = 0), and
//! reads the curvature there: a mesh's are the least-squares second
//! derivatives at every vertex (`mesh/bending.rs`), so the energy is the
//! plate's `½·D·∫(κ₁² + κ₂²)` (Poisson's ratio 0), a quadratic bending
//! model in the sense of Bergou et al. 2006. The forces are linear in the
//! positions and the Hessian `D·Σ_s w_s w_sᵀ ⊗ I₃` is constant, so implicit
//! Euler and the stability bound take it exactly. Rigid motions of the flat
//! sheet store nothing; the model presumes near-isometric motion (stretch
//! springs far stiffer than bending, as in cloth): a patch stretched and
//! turned at once is not read exactly.
//!
//! Damping is the same operator on velocities with coefficient C (N·m·s).

/// The stencils of one cloth, stored as rows of a sparse matrix W: the
/// bending energy is `½·D·|W x|²` per component.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Bending {
    /// Where stencil s's entries start in `nodes` and `weights`; one more
    /// entry than there are stencils (empty when there are none).
    pub offsets: Vec<u32>,
    /// The node of each entry.
    pub nodes: Vec<u32>,
    /// The weight of each entry (1/m): a stencil's weights sum to 0.
    pub weights: Vec<f64>,
    /// Where each group of stencils starts, and one past the last: a group
    /// is up to [`GROUP`] consecutive stencils over the same nodes (a mesh
    /// vertex's three second derivatives), which the kernels read and
    /// write in one pass over those nodes.
    groups: Vec<u32>,
}

/// Most stencils a kernel pass takes at once.
const GROUP: usize = 4;

impl Bending {
    /// Stencils from rows of (node, weight) pairs.
    pub fn from_rows<'a>(rows: impl IntoIterator<Item = &'a [(u32, f64)]>) -> Bending {
        let mut b = Bending::default();
        for row in rows {
            b.push_row(row.iter().copied());
        }
        b.grouped()
    }

    /// These stencils followed by `more`'s.
    pub fn extended(&self, more: &Bending) -> Bending {
        (0..self.len())
            .map(|s| self.row(s))
            .chain((0..more.len()).map(|s| more.row(s)))
            .fold(Bending::default(), |mut b, (nodes, weights)| {
                b.push_row(nodes.iter().copied().zip(weights.iter().copied()));
                b
            })
            .grouped()
    }

    /// These stencils with their groups found: each run of consecutive
    /// stencils over the same nodes, in chunks of at most [`GROUP`].
    fn grouped(mut self) -> Bending {
        self.groups.clear();
        let mut s = 0;
        while s < self.len() {
            self.groups.push(s as u32);
            let nodes = self.row(s).0;
            let mut end = s + 1;
            while end < self.len() && end - s < GROUP && self.row(end).0 == nodes {
                end += 1;
            }
            s = end;
        }
        self.groups.push(self.len() as u32);
        self
    }

    /// Group g's first stencil and its stencils' count.
    #[inline(always)]
    fn group(&self, g: usize) -> (usize, usize) {
        let (a, b) = (self.groups[g] as usize, self.groups[g + 1] as usize);
        (a, b - a)
    }

    /// Number of groups.
    fn groups(&self) -> usize {
        self.groups.len().saturating_sub(1)
    }

    /// Append one stencil (offsets start at 0 with the first).
    fn push_row(&mut self, entries: impl IntoIterator<Item = (u32, f64)>) {
        if self.offsets.is_empty() {
            self.offsets.push(0);
        }
        for (i, w) in entries {
            self.nodes.push(i);
            self.weights.push(w);
        }
        self.offsets.push(self.nodes.len() as u32);
    }

    /// Number of stencils.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Whether there are none (every grid, and a mesh with bend springs).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Stencil s's nodes and weights.
    #[inline(always)]
    pub fn row(&self, s: usize) -> (&[u32], &[f64]) {
        let (a, b) = (self.offsets[s] as usize, self.offsets[s + 1] as usize);
        (&self.nodes[a..b], &self.weights[a..b])
    }

    /// `Σ_i w_si·x_i` of a `[x…, y…, z…]` field of `n` nodes.
    #[inline(always)]
    fn read(nodes: &[u32], weights: &[f64], x: &[f64], n: usize) -> [f64; 3] {
        let mut s = [0.0; 3];
        for (&i, &w) in nodes.iter().zip(weights) {
            let i = i as usize;
            s[0] += w * x[i];
            s[1] += w * x[n + i];
            s[2] += w * x[2 * n + i];
        }
        s
    }

    /// Add `−k·Wᵀ W pos − c·Wᵀ W vel` to `force` (all `[x…, y…, z…]` of
    /// `n` nodes) and return the energy `½·k·|W pos|²` (J). Allocates
    /// nothing.
    pub fn add_forces(&self, k: f64, c: f64, pos: &[f64], vel: &[f64], force: &mut [f64]) -> f64 {
        let mut energy = 0.0;
        for g in 0..self.groups() {
            let e = &mut energy;
            match self.group(g) {
                (s, 1) => self.forces_of::<1>(s, [k, c], pos, vel, force, e),
                (s, 2) => self.forces_of::<2>(s, [k, c], pos, vel, force, e),
                (s, 3) => self.forces_of::<3>(s, [k, c], pos, vel, force, e),
                (s, _) => self.forces_of::<GROUP>(s, [k, c], pos, vel, force, e),
            }
        }
        0.5 * k * energy
    }

    /// The forces of the G stencils from s on, which share their nodes,
    /// added as [`Bending::add_forces`] adds them stencil by stencil (the
    /// same sums in the same order, so the same bits) in one pass over
    /// the nodes; adds their `|W x|²` to `energy`.
    #[inline(always)]
    fn forces_of<const G: usize>(
        &self,
        s: usize,
        [k, c]: [f64; 2],
        pos: &[f64],
        vel: &[f64],
        force: &mut [f64],
        energy: &mut f64,
    ) {
        let n = pos.len() / 3;
        let nodes = self.row(s).0;
        let m = nodes.len();
        let start = self.offsets[s] as usize;
        let weights = &self.weights[start..start + G * m];
        let (mut x, mut v) = ([[0.0; 3]; G], [[0.0; 3]; G]);
        for (e, &i) in nodes.iter().enumerate() {
            let i = i as usize;
            let (p, q) = (
                [pos[i], pos[n + i], pos[2 * n + i]],
                [vel[i], vel[n + i], vel[2 * n + i]],
            );
            for r in 0..G {
                let w = weights[r * m + e];
                for d in 0..3 {
                    x[r][d] += w * p[d];
                    v[r][d] += w * q[d];
                }
            }
        }
        let mut g = [[0.0; 3]; G];
        for r in 0..G {
            *energy += x[r][0] * x[r][0] + x[r][1] * x[r][1] + x[r][2] * x[r][2];
            g[r] = [0, 1, 2].map(|d| -(k * x[r][d] + c * v[r][d]));
        }
        for (e, &i) in nodes.iter().enumerate() {
            let i = i as usize;
            let mut f = [force[i], force[n + i], force[2 * n + i]];
            for r in 0..G {
                let w = weights[r * m + e];
                for d in 0..3 {
                    f[d] += w * g[r][d];
                }
            }
            [force[i], force[n + i], force[2 * n + i]] = f;
        }
    }

    /// Stencil s applied to a `[x…, y…, z…]` field: `Σ_i w_si·x_i`.
    pub fn value(&self, s: usize, x: &[f64]) -> [f64; 3] {
        let (nodes, weights) = self.row(s);
        Self::read(nodes, weights, x, x.len() / 3)
    }

    /// `out += scale·Wᵀ W x` (all `[x…, y…, z…]` of `n` nodes).
    pub fn add_product(&self, scale: f64, x: &[f64], out: &mut [f64]) {
        for g in 0..self.groups() {
            match self.group(g) {
                (s, 1) => self.product_of::<1>(s, scale, x, out),
                (s, 2) => self.product_of::<2>(s, scale, x, out),
                (s, 3) => self.product_of::<3>(s, scale, x, out),
                (s, _) => self.product_of::<GROUP>(s, scale, x, out),
            }
        }
    }

    /// [`Bending::add_product`] of the G stencils from s on, which share
    /// their nodes (the same sums in the same order as stencil by stencil).
    #[inline(always)]
    fn product_of<const G: usize>(&self, s: usize, scale: f64, x: &[f64], out: &mut [f64]) {
        let n = x.len() / 3;
        let nodes = self.row(s).0;
        let m = nodes.len();
        let start = self.offsets[s] as usize;
        let weights = &self.weights[start..start + G * m];
        let mut r = [[0.0; 3]; G];
        for (e, &i) in nodes.iter().enumerate() {
            let i = i as usize;
            let p = [x[i], x[n + i], x[2 * n + i]];
            for (row, rw) in r.iter_mut().enumerate() {
                let w = weights[row * m + e];
                for d in 0..3 {
                    rw[d] += w * p[d];
                }
            }
        }
        let r = r.map(|rw| rw.map(|v| scale * v));
        for (e, &i) in nodes.iter().enumerate() {
            let i = i as usize;
            let mut o = [out[i], out[n + i], out[2 * n + i]];
            for (row, rw) in r.iter().enumerate() {
                let w = weights[row * m + e];
                for d in 0..3 {
                    o[d] += w * rw[d];
                }
            }
            [out[i], out[n + i], out[2 * n + i]] = o;
        }
    }

    /// The operator `Wᵀ W` of these stencils over `n` nodes assembled as
    /// one sparse matrix (allocates; made once per cloth).
    pub fn assembled(&self, n: usize) -> Assembled {
        let mut rows: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
        for s in 0..self.len() {
            let (nodes, weights) = self.row(s);
            for (&a, &wa) in nodes.iter().zip(weights) {
                rows[a as usize].extend(nodes.iter().zip(weights).map(|(&b, &wb)| (b, wa * wb)));
            }
        }
        let mut op = Assembled {
            offsets: Vec::with_capacity(n + 1),
            columns: Vec::new(),
            values: Vec::new(),
        };
        op.offsets.push(0);
        for mut row in rows {
            // Stable: a column's products are summed in stencil order.
            row.sort_by_key(|&(j, _)| j);
            let start = op.columns.len();
            for (j, v) in row {
                if op.columns.len() > start && op.columns.last() == Some(&j) {
                    *op.values.last_mut().expect("a value per column") += v;
                } else {
                    op.columns.push(j);
                    op.values.push(v);
                }
            }
            op.offsets.push(op.columns.len() as u32);
        }
        op
    }

    /// `out[i] += scale·(Wᵀ W)_ii` for every node: the diagonal of the
    /// operator (the same in each component).
    pub fn add_diagonal(&self, scale: f64, out: &mut [f64]) {
        for s in 0..self.len() {
            let (nodes, weights) = self.row(s);
            for (&i, &w) in nodes.iter().zip(weights) {
                out[i as usize] += scale * w * w;
            }
        }
    }

    /// Per node, `Σ_j |(Wᵀ W)_ij|` bounded by `Σ_s |w_si|·Σ_j |w_sj|`:
    /// a Gershgorin row bound of the operator (1/m²).
    pub fn row_bounds(&self, n: usize) -> Vec<f64> {
        let mut out = vec![0.0; n];
        for s in 0..self.len() {
            let (nodes, weights) = self.row(s);
            let total: f64 = weights.iter().map(|w| w.abs()).sum();
            for (&i, &w) in nodes.iter().zip(weights) {
                out[i as usize] += w.abs() * total;
            }
        }
        out
    }

    /// `Σ_s |Σ_i w_si·x_i|²` of `[x, y, z]` points (the energy for D = 2).
    pub fn energy_of(&self, points: &[[f64; 3]]) -> f64 {
        (0..self.len())
            .map(|s| {
                let (nodes, weights) = self.row(s);
                let mut r = [0.0; 3];
                for (&i, &w) in nodes.iter().zip(weights) {
                    let p = points[i as usize];
                    for d in 0..3 {
                        r[d] += w * p[d];
                    }
                }
                r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
            })
            .sum()
    }
}

/// The bending operator `L = Wᵀ W` of a cloth's stencils as one sparse
/// symmetric matrix (rows by node, the same in each component): the
/// forces of [`Bending::add_forces`] in one gather per node instead of a
/// gather and a scatter per stencil. A mesh vertex's stencils span its ring
/// (about 7 nodes) and L's row its two rings (about 19), so a node costs
/// 19 products per field where its three stencils cost 7 × 3 to read and
/// as many to write back; and every node's forces are written once, in
/// order. The sums are the same in exact arithmetic but not in the same
/// order, so not the same bits: the live level's fast path
/// ([`crate::sim::SpringPrecision::F32`]) steps with it, references and
/// estimates with the stencils.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Assembled {
    /// Where node i's row starts in `columns` and `values`; n + 1 entries.
    offsets: Vec<u32>,
    /// The column (node) of each entry, increasing within a row.
    columns: Vec<u32>,
    /// `L_ij = Σ_s w_si·w_sj` (1/m²).
    values: Vec<f64>,
}

impl Assembled {
    /// Entries stored (over all rows).
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether the operator has no entries.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Add `−L (k·pos + c·vel)` to `force` (all `[x…, y…, z…]` of `n`
    /// nodes), as [`Bending::add_forces`] adds `−k·Wᵀ W pos − c·Wᵀ W vel`
    /// up to rounding, and return the energy `½·k·posᵀ L pos` (J) when
    /// `energy`, else NaN (a step whose report shows no energy). `scratch`
    /// holds one node per entry while it works: the combined field is
    /// gathered one node (x, y, z) at a time. Allocates nothing. Inlined
    /// into the step's dispatched closure (`simd`): a node's gather is one
    /// vector load and one fused multiply-add.
    #[inline(always)]
    pub fn add_forces(
        &self,
        k: f64,
        c: f64,
        (pos, vel): (&[f64], &[f64]),
        force: &mut [f64],
        scratch: &mut [[f64; 4]],
        energy: bool,
    ) -> f64 {
        let n = pos.len() / 3;
        assert_eq!(scratch.len(), n, "one scratch entry per node");
        let mut total = f64::NAN;
        if energy {
            for (i, s) in scratch.iter_mut().enumerate() {
                *s = [pos[i], pos[n + i], pos[2 * n + i], 0.0];
            }
            total = 0.0;
            for i in 0..n {
                let l = self.row_times(i, scratch);
                total += pos[i] * l[0] + pos[n + i] * l[1] + pos[2 * n + i] * l[2];
            }
            total *= 0.5 * k;
        }
        let (px, py, pz) = (&pos[..n], &pos[n..2 * n], &pos[2 * n..3 * n]);
        let (vx, vy, vz) = (&vel[..n], &vel[n..2 * n], &vel[2 * n..3 * n]);
        for (i, s) in scratch.iter_mut().enumerate() {
            *s = [k * px[i] + c * vx[i], k * py[i] + c * vy[i], k * pz[i] + c * vz[i], 0.0];
        }
        for i in 0..n {
            let l = self.row_times(i, scratch);
            for d in 0..3 {
                force[d * n + i] -= l[d];
            }
        }
        total
    }

    /// Row i of L times a field of nodes: four running sums over the
    /// row's entries in turn (a fused multiply-add waits on the one before
    /// it in its sum only), added pairwise at the end. The same order on
    /// every instruction set, so the same bits.
    #[inline(always)]
    fn row_times(&self, i: usize, field: &[[f64; 4]]) -> [f64; 4] {
        let (a, b) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
        let (columns, values) = (&self.columns[a..b], &self.values[a..b]);
        let (mut a0, mut a1, mut a2, mut a3) = ([0.0; 4], [0.0; 4], [0.0; 4], [0.0; 4]);
        #[inline(always)]
        fn fma(acc: &mut [f64; 4], w: f64, y: &[f64; 4]) {
            for d in 0..4 {
                acc[d] = w.mul_add(y[d], acc[d]);
            }
        }
        let whole = columns.len() / 4 * 4;
        for e in (0..whole).step_by(4) {
            fma(&mut a0, values[e], &field[columns[e] as usize]);
            fma(&mut a1, values[e + 1], &field[columns[e + 1] as usize]);
            fma(&mut a2, values[e + 2], &field[columns[e + 2] as usize]);
            fma(&mut a3, values[e + 3], &field[columns[e + 3] as usize]);
        }
        for (e, acc) in (whole..columns.len()).zip([&mut a0, &mut a1, &mut a2]) {
            fma(acc, values[e], &field[columns[e] as usize]);
        }
        let mut out = [0.0; 4];
        for d in 0..4 {
            out[d] = (a0[d] + a1[d]) + (a2[d] + a3[d]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn soa(points: &[[f64; 3]]) -> Vec<f64> {
        (0..3).flat_map(|d| points.iter().map(move |p| p[d])).collect()
    }

    /// The kernels take a run of stencils over the same nodes in one pass.
    /// They must give the bits of the definition, stencil by stencil: runs
    /// of 1, 3 and 6 rows (a chunk of 4 and one of 2) and single rows
    /// between them, against the sums written out here.
    #[test]
    fn grouped_stencils_give_the_bits_of_one_stencil_at_a_time() {
        let mut rng = crate::points::generate::SplitMix(7);
        let mut next = move || rng.uniform() - 0.5;
        let n = 23;
        let mut rows: Vec<Vec<(u32, f64)>> = Vec::new();
        for (start, len, repeat) in [(0u32, 5u32, 1), (3, 7, 3), (10, 4, 6), (2, 9, 1), (14, 8, 2), (1, 6, 3)] {
            for _ in 0..repeat {
                rows.push((0..len).map(|e| ((start + 3 * e) % n, next())).collect());
            }
        }
        let b = Bending::from_rows(rows.iter().map(Vec::as_slice));
        assert_eq!(b.len(), 16);
        assert_eq!(b.groups(), 7, "runs of 3, 6 (4 + 2), 2 and 3 rows, and two single rows");
        let field = |next: &mut dyn FnMut() -> f64| (0..3 * n as usize).map(|_| next()).collect::<Vec<f64>>();
        let (pos, vel) = (field(&mut next), field(&mut next));
        let (k, c) = (1.7, 0.3);
        let nn = n as usize;
        let (mut want, mut want_energy) = (field(&mut next), 0.0);
        let mut got = want.clone();
        let (mut want_q, mut got_q) = (vel.clone(), vel.clone());
        for row in &rows {
            let read = |f: &[f64]| {
                let mut s = [0.0; 3];
                for &(i, w) in row {
                    for (d, sd) in s.iter_mut().enumerate() {
                        *sd += w * f[d * nn + i as usize];
                    }
                }
                s
            };
            let (x, v) = (read(&pos), read(&vel));
            want_energy += x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
            let q = x.map(|xd| k * xd);
            for &(i, w) in row {
                for d in 0..3 {
                    want[d * nn + i as usize] += w * -(k * x[d] + c * v[d]);
                    want_q[d * nn + i as usize] += w * q[d];
                }
            }
        }
        let energy = b.add_forces(k, c, &pos, &vel, &mut got);
        b.add_product(k, &pos, &mut got_q);
        assert_eq!(energy.to_bits(), (0.5 * k * want_energy).to_bits());
        for j in 0..3 * nn {
            assert_eq!(got[j].to_bits(), want[j].to_bits(), "force entry {j}");
            assert_eq!(got_q[j].to_bits(), want_q[j].to_bits(), "product entry {j}");
        }
    }

    /// The assembled operator gives the stencils' forces and energy up to
    /// rounding, with one entry per pair of nodes that share a stencil.
    #[test]
    fn the_assembled_operator_is_the_stencils_operator() {
        let mut rng = crate::points::generate::SplitMix(11);
        let mut next = move || rng.uniform() - 0.5;
        let n = 31;
        let rows: Vec<Vec<(u32, f64)>> = (0..40u32)
            .map(|s| (0..7).map(|e| ((s + 4 * e) % n, next())).collect())
            .collect();
        let b = Bending::from_rows(rows.iter().map(Vec::as_slice));
        let op = b.assembled(n as usize);
        let pairs: std::collections::HashSet<(u32, u32)> = rows
            .iter()
            .flat_map(|r| r.iter().flat_map(|&(i, _)| r.iter().map(move |&(j, _)| (i, j))))
            .collect();
        assert_eq!(op.len(), pairs.len(), "one entry per pair of nodes in a stencil");
        let field = |next: &mut dyn FnMut() -> f64| (0..3 * n as usize).map(|_| next()).collect::<Vec<f64>>();
        let (pos, vel, start) = (field(&mut next), field(&mut next), field(&mut next));
        let (k, c) = (1.7, 0.3);
        let (mut want, mut got) = (start.clone(), start.clone());
        let want_energy = b.add_forces(k, c, &pos, &vel, &mut want);
        let mut scratch = vec![[0.0; 4]; n as usize];
        let energy = op.add_forces(k, c, (&pos, &vel), &mut got, &mut scratch, true);
        assert!(
            (energy - want_energy).abs() < 1e-12 * want_energy,
            "{energy} {want_energy}"
        );
        let mut again = start.clone();
        let none = op.add_forces(k, c, (&pos, &vel), &mut again, &mut scratch, false);
        assert!(none.is_nan() && again == got, "without the energy, the same forces");
        let scale = want.iter().map(|f| f.abs()).fold(0.0, f64::max);
        for j in 0..3 * n as usize {
            assert!(
                (got[j] - want[j]).abs() < 1e-12 * scale,
                "entry {j}: {} {}",
                got[j],
                want[j]
            );
        }
    }

    /// Two rows that sum to zero: the forces are minus the gradient of their
    /// energy (central differences) and they sum to zero
    /// (no net force, momentum kept).
    #[test]
    fn forces_are_minus_the_energys_gradient_and_sum_to_zero() {
        let rows: Vec<Vec<(u32, f64)>> = vec![
            vec![(0, -1.3), (1, -0.7), (2, 1.1), (3, 0.9)],
            vec![(1, 2.0), (2, -1.0), (4, -1.0)],
        ];
        let b = Bending::from_rows(rows.iter().map(Vec::as_slice));
        assert_eq!(b.len(), 2);
        let pts = [
            [0.0, 0.1, 0.0],
            [1.0, -0.2, 0.3],
            [0.4, 0.9, -0.1],
            [0.5, -0.8, 0.2],
            [1.7, 0.3, 0.6],
        ];
        let (k, c) = (2.5, 0.0);
        let pos = soa(&pts);
        let vel = vec![0.0; pos.len()];
        let mut f = vec![0.0; pos.len()];
        let e = b.add_forces(k, c, &pos, &vel, &mut f);
        assert!((e - 0.5 * k * b.energy_of(&pts)).abs() < 1e-12 * e.abs().max(1.0));
        let h = 1e-6;
        for j in 0..pos.len() {
            let energy = |x: &[f64]| {
                let mut scratch = vec![0.0; x.len()];
                b.add_forces(k, 0.0, x, &vel, &mut scratch)
            };
            let (mut p, mut m) = (pos.clone(), pos.clone());
            p[j] += h;
            m[j] -= h;
            let grad = (energy(&p) - energy(&m)) / (2.0 * h);
            assert!((f[j] + grad).abs() < 1e-6, "entry {j}: force {} gradient {grad}", f[j]);
        }
        for d in 0..3 {
            let net: f64 = f[d * 5..d * 5 + 5].iter().sum();
            // Row 0 sums to 0, row 1 too: no net force.
            assert!(net.abs() < 1e-12, "net force {net} in component {d}");
        }
        // The product and the diagonal are the same operator as the forces.
        let mut q = vec![0.0; pos.len()];
        b.add_product(k, &pos, &mut q);
        for j in 0..pos.len() {
            assert!((q[j] + f[j]).abs() < 1e-12);
        }
        let mut diag = vec![0.0; 5];
        b.add_diagonal(1.0, &mut diag);
        assert!((diag[1] - (0.7f64.powi(2) + 4.0)).abs() < 1e-12);
    }
}
