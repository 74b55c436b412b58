//! The shadow area against geometry: a flat cloth's shadow is its area, a
//! tilted one's is its area × cos θ, and a cloth folded in half casts the
//! shadow of one layer (folds count once). A drape's folds are counted
//! and its axisymmetric sag measured on draped discs made analytically.

use crate::common;

use common::grid;
use lodcloth::drape::{drape_coefficient, fold_count, ring_profile, shadow_area};
use lodcloth::sim::{Orientation, State};

const PIXEL: f64 = 1e-3;

#[test]
fn a_shadow_is_the_area_a_cloth_covers_seen_from_above_folds_counted_once() {
    let (w, h) = (1.2, 0.8);
    let topo = grid(25, 17, w, h, Orientation::Horizontal);
    let n = topo.n_nodes;
    // Pixel error: at most the perimeter × the pixel.
    let tolerance = 2.0 * (w + h) * PIXEL;
    let flat = State::at_rest(&topo);
    let a = shadow_area(&topo.triangles, &flat.pos, PIXEL);
    assert!((a - w * h).abs() < tolerance, "flat: {a} m², the cloth is {} m²", w * h);

    // Tilted by 60° about x (z → z cos θ, y → z sin θ).
    let theta = 60f64.to_radians();
    let mut tilted = flat.clone();
    for k in 0..n {
        let z = flat.pos[2 * n + k];
        tilted.pos[n + k] = z * theta.sin();
        tilted.pos[2 * n + k] = z * theta.cos();
    }
    let a = shadow_area(&topo.triangles, &tilted.pos, PIXEL);
    assert!((a - w * h * theta.cos()).abs() < tolerance, "tilted 60°: {a} m²");

    // Folded along x = w/2: the right half laid back over the left, 1 cm up.
    let mut folded = flat.clone();
    for k in 0..n {
        let x = flat.pos[k];
        if x > w / 2.0 {
            folded.pos[k] = w - x;
            folded.pos[n + k] = 0.01;
        }
    }
    let a = shadow_area(&topo.triangles, &folded.pos, PIXEL);
    assert!(
        (a - w * h / 2.0).abs() < tolerance,
        "folded in half: {a} m², one layer is {} m²",
        w * h / 2.0
    );

    // A cloth hanging straight down from a support's edge: coefficient 0;
    // one that stays flat over it: 1.
    assert_eq!(drape_coefficient(0.25, 1.0, 0.25), 0.0);
    assert_eq!(drape_coefficient(1.0, 1.0, 0.25), 1.0);
}

/// A flat disc of radius `radius` about (0.3, −0.2) as polar rings (rest
/// positions), and the same nodes (SoA) draped by `drape(ρ, θ)` → (radial
/// distance, height): the fold outline and sag are known exactly.
fn draped_disc(radius: f64, drape: impl Fn(f64, f64) -> (f64, f64)) -> (Vec<[f64; 3]>, Vec<f64>) {
    let centre = [0.3, -0.2];
    let (rings, spokes) = (24, 180);
    let mut nodes = Vec::new();
    for i in 0..rings {
        let rho = radius * (i as f64 + 0.5) / rings as f64;
        for j in 0..spokes {
            nodes.push((rho, std::f64::consts::TAU * (j as f64 + 0.25) / spokes as f64));
        }
    }
    let n = nodes.len();
    let (mut rest, mut pos) = (vec![[0.0; 3]; n], vec![0.0; 3 * n]);
    for (k, &(rho, theta)) in nodes.iter().enumerate() {
        rest[k] = [centre[0] + rho * theta.cos(), 0.0, centre[1] + rho * theta.sin()];
        let (r, y) = drape(rho, theta);
        pos[k] = centre[0] + r * theta.cos();
        pos[n + k] = y;
        pos[2 * n + k] = centre[1] + r * theta.sin();
    }
    (rest, pos)
}

#[test]
fn a_drapes_folds_are_the_maxima_of_its_rims_outline_and_its_sag_is_their_azimuthal_mean() {
    let axis = [0.3, -0.2];
    let (radius, support) = (0.15, 0.09);
    // Beyond the support the cloth hangs, its outline waving n times.
    let wave = |folds: f64, ripple: f64| {
        move |rho: f64, theta: f64| {
            if rho <= support {
                (rho, 0.0)
            } else {
                let r =
                    support + (rho - support) * (0.6 + 0.25 * (folds * theta).cos() + ripple * (31.0 * theta).cos());
                (r, -(rho - support) * 0.8)
            }
        }
    };
    for folds in 4..=11 {
        let (rest, pos) = draped_disc(radius, wave(f64::from(folds), 0.0));
        assert_eq!(fold_count(&rest, &pos, axis), folds as usize, "{folds} folds");
        // A ripple a fifth of the folds' amplitude is not a fold.
        let (rest, pos) = draped_disc(radius, wave(f64::from(folds), 0.05));
        assert_eq!(
            fold_count(&rest, &pos, axis),
            folds as usize,
            "{folds} folds with a ripple"
        );
    }
    // A rim hanging evenly all round has no folds.
    let (rest, even) = draped_disc(radius, |rho, _| {
        (rho.min(support + 0.5 * (rho - support).max(0.0)), -rho)
    });
    assert_eq!(fold_count(&rest, &even, axis), 0);

    // The sag by ring is the azimuthal mean: folds (a height waving with
    // θ) do not change it. Each ring's nodes are at its middle radius ρ,
    // where the sag is −ρ² (and the folded drape's mean is too).
    let sag = |folds: f64| {
        let wave = if folds > 0.0 { 0.01 } else { 0.0 };
        move |rho: f64, theta: f64| (rho, -rho * rho + wave * (folds * theta).cos())
    };
    let rings = 8;
    for folds in [0.0, 5.0, 9.0] {
        let (rest, pos) = draped_disc(radius, sag(folds));
        let profile = ring_profile(&rest, &pos, axis, rings);
        for (i, y) in profile.iter().enumerate() {
            // Ring i holds the disc's polar rings 3i … 3i+2.
            let expected = (0..3)
                .map(|j| radius * ((3 * i + j) as f64 + 0.5) / 24.0)
                .map(|rho| -rho * rho)
                .sum::<f64>()
                / 3.0;
            assert!(
                (y - expected).abs() < 1e-12,
                "ring {i} with {folds} folds: {y} against {expected}"
            );
        }
    }
}
