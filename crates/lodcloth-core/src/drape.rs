//! Drape as a physical measure: the area of a cloth's shadow on the ground
//! and the drape coefficient of a cloth hanging over a support (the Cusick
//! drape tester's measure, BS 5058 / ISO 9073-9):
//! `DC = (A_shadow − A_support) / (A_cloth − A_support)`, 1 for a cloth that
//! stays flat and stiff, 0 for one that hangs straight down from the
//! support's edge. It does not depend on the mesh, so it compares levels of
//! detail by what a tester would see, apart from the eq. 9 error.
//!
//! The shadow is the union of the triangles' projections along y (up), so
//! folded layers count once: measured by marking the centres of square
//! pixels of side `pixel` that some projected triangle covers. Its error is
//! at most about the shadow's perimeter × `pixel`.

/// Area (m²) of the shadow the triangles of `pos` (SoA, y up) cast on a
/// horizontal plane, to pixels of side `pixel` (m, > 0).
pub fn shadow_area(triangles: &[[u32; 3]], pos: &[f64], pixel: f64) -> f64 {
    let n = pos.len() / 3;
    if n == 0 || triangles.is_empty() || !(pixel > 0.0) {
        return 0.0;
    }
    let (xs, zs) = (&pos[..n], &pos[2 * n..3 * n]);
    let lo = [
        xs.iter().copied().fold(f64::INFINITY, f64::min),
        zs.iter().copied().fold(f64::INFINITY, f64::min),
    ];
    let hi = [
        xs.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        zs.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    ];
    if !(lo[0].is_finite() && hi[0].is_finite() && lo[1].is_finite() && hi[1].is_finite()) {
        return f64::NAN;
    }
    let cols = ((hi[0] - lo[0]) / pixel).ceil() as usize + 1;
    let rows = ((hi[1] - lo[1]) / pixel).ceil() as usize + 1;
    let mut covered = vec![false; cols * rows];
    for t in triangles {
        let p = t.map(|k| [xs[k as usize] - lo[0], zs[k as usize] - lo[1]]);
        let cross =
            |a: [f64; 2], b: [f64; 2], c: [f64; 2]| (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        let area2 = cross(p[0], p[1], p[2]);
        if area2 == 0.0 {
            continue; // seen edge-on: no shadow of its own
        }
        let range = |i: usize, len: usize| {
            let v = [p[0][i], p[1][i], p[2][i]];
            let a = v.iter().copied().fold(f64::INFINITY, f64::min);
            let b = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let first = ((a / pixel) - 0.5).ceil().max(0.0) as usize;
            let last = (((b / pixel) - 0.5).floor().max(-1.0) as isize).min(len as isize - 1);
            (first, last)
        };
        let ((c0, c1), (r0, r1)) = (range(0, cols), range(1, rows));
        for r in r0 as isize..=r1 {
            let z = (r as f64 + 0.5) * pixel;
            for c in c0 as isize..=c1 {
                let q = [(c as f64 + 0.5) * pixel, z];
                let w = [cross(p[1], p[2], q), cross(p[2], p[0], q), cross(p[0], p[1], q)];
                let inside = if area2 > 0.0 {
                    w.iter().all(|&x| x >= 0.0)
                } else {
                    w.iter().all(|&x| x <= 0.0)
                };
                if inside {
                    covered[r as usize * cols + c as usize] = true;
                }
            }
        }
    }
    covered.iter().filter(|&&c| c).count() as f64 * pixel * pixel
}

/// The drape coefficient from the shadow's, the flat cloth's and the
/// support's areas (m²).
pub fn drape_coefficient(shadow: f64, cloth: f64, support: f64) -> f64 {
    (shadow - support) / (cloth - support)
}

/// Horizontal (x, z) distance of node `k` of `pos` (SoA) from `axis`, and
/// its azimuth about it.
fn polar(pos: &[f64], k: usize, axis: [f64; 2]) -> (f64, f64) {
    let n = pos.len() / 3;
    let (x, z) = (pos[k] - axis[0], pos[2 * n + k] - axis[1]);
    (x.hypot(z), z.atan2(x))
}

/// Horizontal distance of each rest position from `axis`.
fn rest_reach(rest: &[[f64; 3]], axis: [f64; 2]) -> Vec<f64> {
    rest.iter().map(|p| (p[0] - axis[0]).hypot(p[2] - axis[1])).collect()
}

/// The drape's *nodes* (the folds a Cusick tester counts): local maxima of
/// the rim's outline around `axis` (a vertical line through (x, z)).
///
/// The rim is the nodes whose rest distance from the axis is at least
/// `RIM` of the largest. Their current azimuths fall into `BINS` sectors,
/// each taking its rim's largest horizontal distance (an empty sector its
/// neighbours' mean), smoothed over three sectors. A fold is a maximum
/// of that outline rising at least `PROMINENCE` of the outline's range
/// above both minima around it. 0 for a rim that is
/// level (a range under `LEVEL` of its largest distance) or has a sector
/// empty with both neighbours (a rim too coarse for the sectors).
pub fn fold_count(rest: &[[f64; 3]], pos: &[f64], axis: [f64; 2]) -> usize {
    const RIM: f64 = 0.9;
    const BINS: usize = 72;
    const PROMINENCE: f64 = 0.1;
    const LEVEL: f64 = 1e-3;
    let n = pos.len() / 3;
    let reach = rest_reach(rest, axis);
    let far = reach.iter().copied().fold(0.0, f64::max);
    let mut outline = [f64::NAN; BINS];
    for k in (0..n).filter(|&k| reach[k] >= RIM * far) {
        let (r, phi) = polar(pos, k, axis);
        let bin = (((phi + std::f64::consts::PI) / std::f64::consts::TAU * BINS as f64) as usize).min(BINS - 1);
        if !(outline[bin] >= r) {
            outline[bin] = r;
        }
    }
    let filled: Vec<f64> = (0..BINS)
        .map(|b| {
            if outline[b].is_finite() {
                return outline[b];
            }
            let around = [outline[(b + BINS - 1) % BINS], outline[(b + 1) % BINS]];
            let known: Vec<f64> = around.into_iter().filter(|r| r.is_finite()).collect();
            if known.is_empty() {
                f64::NAN
            } else {
                known.iter().sum::<f64>() / known.len() as f64
            }
        })
        .collect();
    if filled.iter().any(|r| !r.is_finite()) {
        return 0;
    }
    let smooth: Vec<f64> = (0..BINS)
        .map(|b| (filled[(b + BINS - 1) % BINS] + filled[b] + filled[(b + 1) % BINS]) / 3.0)
        .collect();
    let (lo, hi) = smooth
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &r| (a.min(r), b.max(r)));
    let threshold = PROMINENCE * (hi - lo);
    if !(hi - lo >= LEVEL * hi) {
        return 0;
    }
    // Walk the closed outline from its lowest sector: a fold is counted
    // when the outline, having risen `threshold` above the last minimum,
    // falls `threshold` below the maximum since (hysteresis, so a ripple
    // on a fold's flank is not a fold of its own).
    let start = (0..BINS).min_by(|&a, &b| smooth[a].total_cmp(&smooth[b])).unwrap_or(0);
    let (mut folds, mut low, mut high, mut rising) = (0, smooth[start], smooth[start], true);
    for i in 1..=BINS {
        let r = smooth[(start + i) % BINS];
        if rising {
            if r < low {
                (low, high) = (r, r);
            }
            high = high.max(r);
            if high - low >= threshold && high - r >= threshold {
                folds += 1;
                (rising, low) = (false, r);
            }
        } else {
            low = low.min(r);
            if r - low >= threshold {
                (rising, high) = (true, r);
            }
        }
    }
    folds
}

/// The drape's axisymmetric part: the mean height (y) of the nodes of
/// `pos` in each of `rings` rings of rest distance from `axis`, the rings
/// splitting 0 … the largest rest distance evenly (NaN for an empty
/// ring). Two levels with the same profile sag alike, wherever their
/// folds formed: their difference is the material's, not the folds'.
pub fn ring_profile(rest: &[[f64; 3]], pos: &[f64], axis: [f64; 2], rings: usize) -> Vec<f64> {
    let n = pos.len() / 3;
    let reach = rest_reach(rest, axis);
    let far = reach.iter().copied().fold(0.0, f64::max);
    let mut sum = vec![(0.0, 0usize); rings];
    if rings == 0 || !(far > 0.0) {
        return vec![f64::NAN; rings];
    }
    for k in 0..n {
        let ring = ((reach[k] / far * rings as f64) as usize).min(rings - 1);
        sum[ring].0 += pos[n + k];
        sum[ring].1 += 1;
    }
    sum.iter()
        .map(|&(s, c)| if c > 0 { s / c as f64 } else { f64::NAN })
        .collect()
}

/// A twin of `sim`'s run: every node of its state raised or lowered (y) by
/// a normal draw of standard deviation `jitter` (m), seeded by `seed`.
/// Where a symmetric drape breaks into folds is decided by rounding, so one
/// run is one draw of its drape coefficient; runs from a few such twins
/// give its spread (the lab's NOTEBOOK.md, "One run is one draw of the drape").
pub fn jitter_heights(sim: &mut crate::sim::Simulation, seed: u64, jitter: f64) {
    let mut rng = crate::points::generate::SplitMix(seed);
    let mut state = sim.state().clone();
    let n = sim.topology().n_nodes;
    for y in &mut state.pos[n..2 * n] {
        *y += jitter * rng.gaussian();
    }
    sim.set_state(state).expect("the simulation's own state");
}
