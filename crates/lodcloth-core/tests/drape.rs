//! The shadow area against geometry: a flat cloth's shadow is its area, a
//! tilted one's is its area × cos θ, and a cloth folded in half casts the
//! shadow of one layer (folds count once).

use crate::common;

use common::grid;
use lodcloth::drape::{drape_coefficient, shadow_area};
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
