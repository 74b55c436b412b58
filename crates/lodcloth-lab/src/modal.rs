//! Mode-selective bending: a level's bending stencils stiffened mode by
//! mode towards the reference's spectrum.
//!
//! A coarse level of a mesh cloth reads its bending with fewer, larger
//! stencils. Its softest modes (the long waves of the clamp's overhang)
//! match the reference's; above them it is softer, the coarser the more
//! (NOTEBOOK.md, "Bending for the drape, or for the step after a switch").
//! A factor on the bending rigidity D moves every mode at once: it buys the
//! drape coefficient with the softest modes made too stiff. Here each mode
//! is moved on its own.
//!
//! With the pinned vertices held, the free vertices' vertical modes solve
//! `W_ff z = λ A_f z` (W the stencils' quadratic form, A the lumped areas),
//! or `B v = λ v` with `B = A_f^-½ W_ff A_f^-½` and `v = A_f^½ z`.
//! Appending one row `r = √((s − 1)·λ_j)·A_f^½ v_j` to the stencils adds
//! `(s − 1)·λ_j·v_j v_jᵀ` to B: mode j's eigenvalue becomes `s·λ_j` and,
//! the v's being orthogonal, no other mode moves. [`stiffening`] does that
//! for a band of modes with `s_j = λ_ref,j / λ_j` (modes paired by their
//! order, never softened), and gives the row weights on the pinned
//! vertices that make it vanish on every affine map of the rest shape, as
//! a stencil does: a pinned cloth at rest feels nothing from it.
//!
//! Dense: two symmetric eigendecompositions of the free vertices, whose
//! time grows as the cube of their number (the Cusick reference's 792 and
//! its two levels' 635 and 404, with the levels made and stiffened, take
//! 3.3 s: `drape_scan spectrum --clamped --modal 12..`). A
//! 20k-vertex reference needs a sparse solver for its few hundred softest
//! modes; not here.

use std::ops::Range;

use nalgebra::{DMatrix, Matrix4, Vector4};

use lodcloth_core::sim::{Bending, Topology};

/// Why a correction could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ModalError {
    /// A cloth without bending stencils.
    #[error("the {which} has no bending stencils (a mesh cloth with a bending rigidity has)")]
    NoStencils {
        /// "reference" or "level".
        which: &'static str,
    },
    /// More free vertices than a dense eigendecomposition is for.
    #[error("the {which} has {free} free vertices; the dense eigendecomposition here stops at {MAX_DENSE}")]
    TooLarge {
        /// "reference" or "level".
        which: &'static str,
        /// Its free vertices.
        free: usize,
    },
    /// Too few pins to hold the correction's rows at rest.
    #[error("the level's pinned vertices must span the rest plane (three not on a line) to hold a mode row at rest")]
    Pins,
    /// A band with no mode both cloths have.
    #[error("modes {start}..{end} asked for, the level has {level} and the reference {reference} (free vertices)")]
    Band {
        /// First mode asked for.
        start: usize,
        /// One past the last.
        end: usize,
        /// The level's modes.
        level: usize,
        /// The reference's modes.
        reference: usize,
    },
}

/// The most free vertices [`ClampedModes::of`] decomposes (a dense
/// symmetric eigendecomposition, its time the cube of their number: about
/// 130 times the Cusick reference's at 792).
pub const MAX_DENSE: usize = 4000;

/// The bending modes of a cloth's free vertices, every pinned vertex held.
#[derive(Debug, Clone)]
pub struct ClampedModes {
    /// The free vertices, ascending.
    pub free: Vec<u32>,
    /// Eigenvalues, ascending (1/m⁴).
    pub values: Vec<f64>,
    /// Column j is mode j in the area-scaled basis `A_f^½ z`, unit length.
    pub vectors: DMatrix<f64>,
}

impl ClampedModes {
    /// The modes of `topology`'s stencils with the vertices `pinned` says
    /// held (`which` names the cloth in an error).
    ///
    /// # Errors
    /// A cloth without stencils, or with more than [`MAX_DENSE`] free
    /// vertices.
    pub fn of(topology: &Topology, pinned: &[bool], which: &'static str) -> Result<ClampedModes, ModalError> {
        let n = topology.n_nodes;
        assert_eq!(pinned.len(), n, "one pinned flag per node");
        if topology.bending.is_empty() {
            return Err(ModalError::NoStencils { which });
        }
        let free: Vec<u32> = (0..n as u32).filter(|&i| !pinned[i as usize]).collect();
        if free.len() > MAX_DENSE {
            return Err(ModalError::TooLarge {
                which,
                free: free.len(),
            });
        }
        let mut slot = vec![usize::MAX; n];
        for (f, &i) in free.iter().enumerate() {
            slot[i as usize] = f;
        }
        let areas = &topology.node_areas;
        let m = free.len();
        let mut b = DMatrix::<f64>::zeros(m, m);
        for s in 0..topology.bending.len() {
            let (nodes, weights) = topology.bending.row(s);
            for (&i, &wi) in nodes.iter().zip(weights) {
                let a = slot[i as usize];
                if a == usize::MAX {
                    continue;
                }
                for (&j, &wj) in nodes.iter().zip(weights) {
                    let c = slot[j as usize];
                    if c != usize::MAX {
                        b[(a, c)] += wi * wj / (areas[i as usize] * areas[j as usize]).sqrt();
                    }
                }
            }
        }
        let eigen = b.symmetric_eigen();
        let mut order: Vec<usize> = (0..m).collect();
        order.sort_by(|&i, &j| eigen.eigenvalues[i].total_cmp(&eigen.eigenvalues[j]));
        let values = order.iter().map(|&i| eigen.eigenvalues[i]).collect();
        let vectors = DMatrix::from_fn(m, m, |r, c| eigen.eigenvectors[(r, order[c])]);
        Ok(ClampedModes { free, values, vectors })
    }

    /// How many modes (free vertices).
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether there are none (every vertex pinned).
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }
}

/// Which of `n` nodes a set of pinned node indices holds.
pub fn pinned_flags(n: usize, pins: impl IntoIterator<Item = u32>) -> Vec<bool> {
    let mut pinned = vec![false; n];
    for i in pins {
        pinned[i as usize] = true;
    }
    pinned
}

/// Stencil rows to append to `level`'s that raise each of its modes j in
/// `band` to `s_j·λ_j`, `s_j = max(1, λ_ref,j / λ_j)` (`reference` the
/// reference's modes, paired by order), and leave every other mode as it
/// is. Each row carries weights on the pinned vertices (least norm) so it
/// sums to zero against 1, X, Y and Z of the rest shape. Modes already as
/// stiff as the reference's get no row. The band's end is cut to the modes
/// both cloths have (`FIRST..usize::MAX`: every mode from FIRST on).
pub fn stiffening(
    level: &Topology,
    pinned: &[bool],
    modes: &ClampedModes,
    reference: &ClampedModes,
    band: Range<usize>,
) -> Result<Bending, ModalError> {
    if level.bending.is_empty() {
        return Err(ModalError::NoStencils { which: "level" });
    }
    let band = band.start..band.end.min(modes.len()).min(reference.len());
    if band.is_empty() {
        return Err(ModalError::Band {
            start: band.start,
            end: band.end,
            level: modes.len(),
            reference: reference.len(),
        });
    }
    let held: Vec<u32> = (0..level.n_nodes as u32).filter(|&i| pinned[i as usize]).collect();
    let rest = &level.rest_positions;
    // Moments [1, X, Y, Z] about the pins' centroid; a row's pinned weights
    // p solve C p = −b (b the free weights' moments) with least |p|:
    // p = −Cᵀ (C Cᵀ)⁺ b. A flat rest shape makes C Cᵀ rank 3.
    let centre = held.iter().fold([0.0; 3], |c, &i| {
        let x = rest[i as usize];
        [c[0] + x[0], c[1] + x[1], c[2] + x[2]]
    });
    let centre = centre.map(|c| c / held.len().max(1) as f64);
    let moments = |i: u32| {
        let x = rest[i as usize];
        Vector4::new(1.0, x[0] - centre[0], x[1] - centre[1], x[2] - centre[2])
    };
    let mut gram = Matrix4::<f64>::zeros();
    for &i in &held {
        let c = moments(i);
        gram += c * c.transpose();
    }
    let svd = gram.svd(true, true);
    let largest = svd.singular_values.max();
    let rank = svd.singular_values.iter().filter(|&&s| s > 1e-9 * largest).count();
    if held.len() < 3 || rank < 3 {
        return Err(ModalError::Pins);
    }
    let inverse = svd.pseudo_inverse(1e-9 * largest).expect("the SVD has both factors");
    let areas = &level.node_areas;
    let mut rows: Vec<Vec<(u32, f64)>> = Vec::new();
    for j in band {
        let (lambda, target) = (modes.values[j], reference.values[j]);
        if !(lambda > 0.0 && target > lambda) {
            continue;
        }
        let scale = (target - lambda).sqrt();
        let v = modes.vectors.column(j);
        let mut row: Vec<(u32, f64)> = modes
            .free
            .iter()
            .enumerate()
            .map(|(f, &i)| (i, scale * areas[i as usize].sqrt() * v[f]))
            .collect();
        let b = row.iter().fold(Vector4::zeros(), |b, &(i, w)| b + moments(i) * w);
        let y = inverse * b;
        row.extend(held.iter().map(|&i| (i, -moments(i).dot(&y))));
        rows.push(row);
    }
    Ok(Bending::from_rows(rows.iter().map(Vec::as_slice)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use lodcloth_core::mesh::{generate, plate_topology};

    /// A disc in the x–z plane clamped at its middle, with the scenes'
    /// vertex stencils.
    fn clamped_disc() -> (Topology, Vec<bool>) {
        let mesh = generate::disc(0.15, 0.0, 0.012);
        let pinned: Vec<bool> = mesh
            .positions
            .iter()
            .map(|x| (x[0] * x[0] + x[2] * x[2]).sqrt() < 0.05)
            .collect();
        let topology = plate_topology(&mesh, &pinned).expect("a flat disc");
        (topology, pinned)
    }

    #[test]
    fn a_band_moves_its_modes_to_the_reference_and_leaves_the_rest() {
        let (topology, pinned) = clamped_disc();
        let modes = ClampedModes::of(&topology, &pinned, "disc").expect("stencils");
        // A "reference" twice as stiff in modes 5..20.
        let mut reference = modes.clone();
        for v in &mut reference.values[5..20] {
            *v *= 2.0;
        }
        let rows = stiffening(&topology, &pinned, &modes, &reference, 3..20).expect("stiffens");
        assert_eq!(rows.len(), 15, "no row for modes already as stiff");
        let mut stiffer = topology.clone();
        stiffer.bending = stiffer.bending.extended(&rows);
        let after = ClampedModes::of(&stiffer, &pinned, "disc").expect("stencils");
        let mut want: Vec<f64> = modes.values.clone();
        for v in &mut want[5..20] {
            *v *= 2.0;
        }
        want.sort_by(f64::total_cmp);
        for (j, (&a, &w)) in after.values.iter().zip(&want).enumerate() {
            assert!((a - w).abs() <= 1e-8 * w.abs().max(1.0), "mode {j}: {a} against {w}");
        }
    }

    #[test]
    fn the_rows_read_nothing_on_an_affine_map_of_the_rest_shape() {
        let (topology, pinned) = clamped_disc();
        let modes = ClampedModes::of(&topology, &pinned, "disc").expect("stencils");
        let mut reference = modes.clone();
        for v in &mut reference.values {
            *v *= 1.5;
        }
        let rows = stiffening(&topology, &pinned, &modes, &reference, 0..40).expect("stiffens");
        let n = topology.n_nodes;
        let mut x = vec![0.0; 3 * n];
        for (i, p) in topology.rest_positions.iter().enumerate() {
            // A rotation about z, a shear, a lift and a shift.
            x[i] = 0.8 * p[0] - 0.6 * p[1] + 0.3;
            x[n + i] = 0.6 * p[0] + 0.8 * p[1] + 0.2 * p[0] - 0.1;
            x[2 * n + i] = p[2] + 0.4 * p[0] - 0.7 * p[1] + 1.0;
        }
        for s in 0..rows.len() {
            let (_, w) = rows.row(s);
            let scale: f64 = w.iter().map(|w| w.abs()).sum();
            for (d, r) in rows.value(s, &x).iter().enumerate() {
                assert!(r.abs() <= 1e-12 * scale, "row {s} reads {r} on component {d}");
            }
        }
    }

    #[test]
    fn a_band_past_the_modes_or_a_cloth_held_on_a_line_is_refused() {
        let (topology, pinned) = clamped_disc();
        let modes = ClampedModes::of(&topology, &pinned, "disc").expect("stencils");
        let err = stiffening(&topology, &pinned, &modes, &modes, modes.len()..usize::MAX).unwrap_err();
        assert!(matches!(err, ModalError::Band { .. }), "{err}");
        let line: Vec<bool> = topology
            .rest_positions
            .iter()
            .map(|x| x[2].abs() < 1e-9 && x[0].abs() < 0.05)
            .collect();
        let modes = ClampedModes::of(&topology, &line, "disc").expect("stencils");
        let mut reference = modes.clone();
        reference.values.iter_mut().for_each(|v| *v *= 2.0);
        let err = stiffening(&topology, &line, &modes, &reference, 3..10).unwrap_err();
        assert!(matches!(err, ModalError::Pins), "{err}");
    }
}
