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
