//! The one camera every cloth picture is seen by, and the framing and
//! shading helpers the renders and error maps share.

use crate::sim::vec3::{cross, dot};

/// Orthographic camera of every cloth picture: azimuth 35° about y,
/// elevation 20°. Returns (right, up, depth) per point.
pub fn project(points: &[[f64; 3]]) -> Vec<(f64, f64, f64)> {
    let (az, el) = (35f64.to_radians(), 20f64.to_radians());
    let forward = [-el.cos() * az.sin(), -el.sin(), -el.cos() * az.cos()];
    let right = [az.cos(), 0.0, -az.sin()];
    let up = cross(right, forward);
    points
        .iter()
        .map(|p| (dot(*p, right), dot(*p, up), dot(*p, forward)))
        .collect()
}

/// Centre and side of a square that holds every finite projected point
/// (10 % margin); `None` when there is none.
pub fn frame(projected: &[Vec<(f64, f64, f64)>]) -> Option<(f64, f64, f64)> {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y, _) in projected.iter().flatten() {
        if x.is_finite() && y.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    (x0 <= x1).then(|| (0.5 * (x0 + x1), 0.5 * (y0 + y1), (x1 - x0).max(y1 - y0).max(1e-9) * 1.1))
}

/// `a` scaled to unit length (zero stays zero).
pub fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    if l > 0.0 {
        a.map(|x| x / l)
    } else {
        a
    }
}
