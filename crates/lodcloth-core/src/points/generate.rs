//! Test shapes for point-sampled surfaces: a sphere (3,203 points is the
//! paper's example), a hemisphere "hat", a flat square patch, and noisy
//! variants of each. Points are spread evenly (a Fibonacci lattice on the
//! curved shapes, the R2 low-discrepancy sequence on the patch), so no two
//! coincide and no four lie exactly on a circle in a regular pattern.

use std::f64::consts::{PI, TAU};

use super::PointCloud;
use crate::sim::vec3::{add, normalize, scale, V3};

/// A generated shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// Sphere of radius `size` centred at the origin.
    Sphere,
    /// Upper hemisphere (z > 0) of radius `size`, down to the rim.
    Hat,
    /// Square `size × size` in the z = 0 plane centred at the origin.
    Patch,
}

impl Shape {
    /// Every shape, in the order the command line lists them.
    pub const ALL: [Shape; 3] = [Shape::Sphere, Shape::Hat, Shape::Patch];

    /// The shape's name in scene files and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Shape::Sphere => "sphere",
            Shape::Hat => "hat",
            Shape::Patch => "patch",
        }
    }

    /// The shape called `name`, if any.
    pub fn from_name(name: &str) -> Option<Shape> {
        Shape::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Surface area of the shape of size `size` (m²).
    pub fn area(self, size: f64) -> f64 {
        match self {
            Shape::Sphere => 4.0 * PI * size * size,
            Shape::Hat => 2.0 * PI * size * size,
            Shape::Patch => size * size,
        }
    }
}

/// Generate `count` points of `shape` with size `size` (radius or side, m)
/// and outward unit normals. With `noise > 0`, every point moves along its
/// normal by a Gaussian of standard deviation `noise` × the mean spacing and
/// the normals are dropped (a noisy scan has none); `seed` fixes the noise.
pub fn generate(shape: Shape, count: usize, size: f64, noise: f64, seed: u64) -> PointCloud {
    let golden = PI * (3.0 - 5f64.sqrt());
    let mut positions = Vec::with_capacity(count);
    let mut normals = Vec::with_capacity(count);
    match shape {
        Shape::Sphere | Shape::Hat => {
            // Equal-area bands in z: the sphere over z ∈ [−1, 1], the hat over [0, 1].
            let span = if shape == Shape::Sphere { 2.0 } else { 1.0 };
            for i in 0..count {
                let z = 1.0 - span * (i as f64 + 0.5) / count as f64;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let a = golden * i as f64;
                let n = [r * a.cos(), r * a.sin(), z];
                positions.push(scale(n, size));
                normals.push(n);
            }
        }
        Shape::Patch => {
            // R2 sequence (Roberts 2018): plastic-number steps, low discrepancy.
            let g = 1.324_717_957_244_746;
            let (a1, a2) = (1.0 / g, 1.0 / (g * g));
            for i in 0..count {
                let x = (0.5 + a1 * i as f64).fract();
                let y = (0.5 + a2 * i as f64).fract();
                positions.push([(x - 0.5) * size, (y - 0.5) * size, 0.0]);
                normals.push([0.0, 0.0, 1.0]);
            }
        }
    }
    if noise > 0.0 {
        let spacing = (shape.area(size) / count as f64).sqrt();
        let mut rng = SplitMix(seed);
        for (p, n) in positions.iter_mut().zip(&normals) {
            *p = add(*p, scale(*n, noise * spacing * rng.gaussian()));
        }
        return PointCloud::new(positions);
    }
    PointCloud {
        positions,
        normals: Some(
            normals
                .into_iter()
                .map(|n| normalize(n).unwrap_or([0.0, 0.0, 1.0]))
                .collect(),
        ),
    }
}

/// SplitMix64 (Steele et al. 2014): a small, fast, reproducible generator.
#[derive(Debug, Clone)]
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    pub fn gaussian(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

/// Index of the point farthest along `dir` (e.g. the top of the hat).
pub fn extreme_point(points: &[V3], dir: V3) -> usize {
    points
        .iter()
        .enumerate()
        .max_by(|a, b| crate::sim::vec3::dot(*a.1, dir).total_cmp(&crate::sim::vec3::dot(*b.1, dir)))
        .map_or(0, |(i, _)| i)
}
