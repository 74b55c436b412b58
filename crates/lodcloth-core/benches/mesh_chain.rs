//! What making a mesh cloth's levels costs (issue 23's target: a 20k-vertex
//! mesh simplified, correlated and given springs in ≤ 2 s): for a flat disc
//! and a skirt (an open tube) of about `--vertices` vertices, the time of
//! each step for levels at 40 %, 15 % and 5 % of the vertices, and of the
//! whole chain.
//!
//! `cargo bench -p lodcloth-core --bench mesh_chain -- [--vertices 20000]`
//!
//! Per level: simplification (meshoptimizer, pins locked), springs and
//! masses ([`mesh_topology`], [`mesh_material`]), the bending stencils a
//! flat mesh gets with a bending rigidity ([`bending_stencils`]; the disc
//! only, a skirt is not flat), and the correlation both ways (reference →
//! level, level → reference: closest points on the rest surface).
//! Single-threaded; each figure is the best of three runs.
use std::time::Instant;

use lodcloth_core::lod::Correlation;
use lodcloth_core::mesh::{bending_stencils, generate, mesh_material, mesh_topology, simplify, TriMesh};
use lodcloth_core::sim::{Membrane, Moduli};

fn arg<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(String::as_str)
}

/// Best wall time of three runs of `f` (s), and its last result.
fn best<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut out = None;
    let mut t = f64::INFINITY;
    for _ in 0..3 {
        let start = Instant::now();
        let r = f();
        t = t.min(start.elapsed().as_secs_f64());
        out = Some(r);
    }
    (t, out.expect("ran"))
}

fn membrane() -> Membrane {
    let m = Moduli {
        stretch_u: 400.0,
        stretch_v: 400.0,
        shear: 60.0,
        bend_u: 80.0,
        bend_v: 80.0,
    };
    Membrane {
        stiffness: m,
        damping: m,
    }
}

fn chain(name: &str, reference: &TriMesh, locked: &[bool]) {
    let n = reference.vertices();
    println!(
        "\n{name}: {n} vertices, {} triangles, {} pinned",
        reference.triangles.len(),
        locked.iter().filter(|&&l| l).count()
    );
    println!(
        "| level (vertices) | simplify (ms) | springs (ms) | stencils (ms) | correlate ↓ (ms) | correlate ↑ (ms) | level total (ms) |"
    );
    println!("|---|---|---|---|---|---|---|");
    // The stencils' time when the mesh is flat (0 when it is not).
    let stencils = |mesh: &TriMesh, pinned: &[bool]| {
        let (t, made) = best(|| bending_stencils(mesh, pinned).is_ok());
        if made {
            t
        } else {
            0.0
        }
    };
    let (t_ref, fine) = best(|| mesh_topology(reference));
    let t_ref_stencils = stencils(reference, locked);
    let mut total = t_ref + t_ref_stencils;
    for share in [0.40, 0.15, 0.05] {
        let target = (n as f64 * share).round() as usize;
        let (t_s, level) = best(|| simplify(reference, target, locked, name).expect("simplifies"));
        let (t_t, coarse) = best(|| {
            let topo = mesh_topology(&level.mesh);
            let material = mesh_material(&membrane(), &topo, None);
            (topo, material)
        });
        let pinned: Vec<bool> = level.source.iter().map(|&k| locked[k as usize]).collect();
        let t_b = stencils(&level.mesh, &pinned);
        let (t_down, _) = best(|| Correlation::between(&fine, &coarse.0).expect("correlates"));
        let (t_up, _) = best(|| Correlation::between(&coarse.0, &fine).expect("correlates"));
        let sum = t_s + t_t + t_b + t_down + t_up;
        total += sum;
        println!(
            "| {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
            level.mesh.vertices(),
            1e3 * t_s,
            1e3 * t_t,
            1e3 * t_b,
            1e3 * t_down,
            1e3 * t_up,
            1e3 * sum
        );
    }
    println!(
        "{name}: reference springs {:.1} ms, stencils {:.1} ms; the whole chain (three levels) {:.3} s (target ≤ 2 s)",
        1e3 * t_ref,
        1e3 * t_ref_stencils,
        total
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let vertices: usize = arg(&args, "--vertices").map_or(20_000, |v| v.parse().expect("--vertices N"));
    // A disc of K = R/a rings has 1 + 3K(K + 1) ≈ 3(R/a)² vertices.
    let radius = 0.15;
    let edge = radius * (3.0 / vertices as f64).sqrt();
    let disc = generate::disc(radius, 0.0, edge);
    let pinned: Vec<bool> = disc
        .positions
        .iter()
        .map(|p| (p[0] * p[0] + p[2] * p[2]).sqrt() <= 0.2 * radius)
        .collect();
    chain("disc", &disc, &pinned);
    // A skirt of about the same count: circumference ≈ 2π·0.25 m, length 0.6 m.
    let skirt_edge = (std::f64::consts::TAU * 0.25 * 0.6 / (0.866 * vertices as f64)).sqrt();
    let skirt = generate::skirt(0.2, 0.3, 0.6, 1.0, skirt_edge);
    let mut waist = vec![false; skirt.vertices()];
    for &k in &skirt.groups["waist"] {
        waist[k as usize] = true;
    }
    chain("skirt", &skirt, &waist);
}
