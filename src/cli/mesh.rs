//! `lodcloth mesh`: cloth meshes. `make` writes a generated mesh (the
//! shipped Cusick specimen and skirt come from it); `info` reads a user's
//! file as a scene would and shows the level chain it makes.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Subcommand;

use lodcloth::lod::Correlation;
use lodcloth::mesh::{self, generate, TriMesh};

/// Mesh tools.
#[derive(Debug, Subcommand)]
pub enum Mesh {
    /// Write a generated near-equilateral mesh as OBJ.
    Make {
        #[command(subcommand)]
        shape: Shape,
        /// Output file (.obj).
        #[arg(long, short)]
        out: PathBuf,
    },
    /// Read a mesh file (.obj, .ply, .gltf, .glb) as a scene would: its
    /// size, groups and material coordinates; then simplify it to each
    /// --levels vertex count and show what every level keeps and costs.
    Info {
        /// The mesh file.
        file: PathBuf,
        /// Vertex counts to simplify to, comma separated, written as a
        /// config's levels or bare (e.g. 2000v,800v or 2000,800).
        #[arg(long, value_delimiter = ',', value_parser = vertex_count)]
        levels: Vec<usize>,
    },
}

/// A generated mesh.
#[derive(Debug, Subcommand)]
pub enum Shape {
    /// A flat disc in the x–z plane, centred on the y axis.
    Disc {
        /// Radius (m).
        #[arg(long)]
        radius: f64,
        /// Height of its plane (m).
        #[arg(long, default_value_t = 0.0)]
        y: f64,
        /// Edge length (m).
        #[arg(long)]
        edge: f64,
    },
    /// A flat width × height sheet in the x–z plane at y = 0.
    Sheet {
        /// Along x (m).
        #[arg(long)]
        width: f64,
        /// Along z (m).
        #[arg(long)]
        height: f64,
        /// Edge length (m).
        #[arg(long)]
        edge: f64,
    },
    /// An open tube from radius `top` at height `y` down to `bottom`.
    Skirt {
        /// Radius at the waist (m).
        #[arg(long)]
        top: f64,
        /// Radius at the hem (m).
        #[arg(long)]
        bottom: f64,
        /// Waist to hem (m).
        #[arg(long)]
        length: f64,
        /// Height of the waist (m).
        #[arg(long)]
        y: f64,
        /// Edge length (m).
        #[arg(long)]
        edge: f64,
    },
}

pub fn run(m: Mesh) -> Result<()> {
    match m {
        Mesh::Make { shape, out } => make(shape, out),
        Mesh::Info { file, levels } => info(file, &levels),
    }
}

fn make(shape: Shape, out: PathBuf) -> Result<()> {
    let positive = |name: &str, x: f64| {
        anyhow::ensure!(x.is_finite() && x > 0.0, "--{name} must be positive, got {x}");
        Ok(())
    };
    let (mesh, what) = match shape {
        Shape::Disc { radius, y, edge } => {
            positive("radius", radius)?;
            positive("edge", edge)?;
            anyhow::ensure!(
                radius / edge <= 400.0,
                "--edge is too small for the radius (over 500k vertices)"
            );
            (
                generate::disc(radius, y, edge),
                format!("disc radius {radius} m at y = {y} m, edge {edge} m"),
            )
        }
        Shape::Sheet { width, height, edge } => {
            positive("width", width)?;
            positive("height", height)?;
            positive("edge", edge)?;
            anyhow::ensure!(
                width * height / (edge * edge) <= 5e5,
                "--edge is too small for the sheet (over 500k vertices)"
            );
            (
                generate::sheet(width, height, edge),
                format!("sheet {width} × {height} m, edge {edge} m"),
            )
        }
        Shape::Skirt {
            top,
            bottom,
            length,
            y,
            edge,
        } => {
            for (name, x) in [("top", top), ("bottom", bottom), ("length", length), ("edge", edge)] {
                positive(name, x)?;
            }
            anyhow::ensure!(
                top.max(bottom) * length / (edge * edge) <= 1e5,
                "--edge is too small for the skirt (over 500k vertices)"
            );
            (
                generate::skirt(top, bottom, length, y, edge),
                format!(
                    "skirt waist radius {top} m at y = {y} m, hem radius {bottom} m, length {length} m, edge {edge} m"
                ),
            )
        }
    };
    let comment = format!(
        "lodcloth mesh make: {what}\n{} vertices, {} triangles, {:.6} m²",
        mesh.vertices(),
        mesh.triangles.len(),
        mesh.area()
    );
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&out, generate::to_obj(&mesh, &comment)).with_context(|| format!("writing {}", out.display()))?;
    println!("{}: {}", out.display(), comment.replace('\n', "; "));
    Ok(())
}

/// `915v`, `915 vertices` or `915`: a mesh level's vertex count.
fn vertex_count(s: &str) -> Result<usize, String> {
    let t = s.trim();
    let digits = t.strip_suffix("vertices").or_else(|| t.strip_suffix('v')).unwrap_or(t);
    digits
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a vertex count; write e.g. 915v or 915"))
}

fn info(file: PathBuf, levels: &[usize]) -> Result<()> {
    let mesh = mesh::load(&file)?;
    describe(&file, &mesh);
    let fine = mesh::mesh_topology(&mesh);
    let (shortest, longest) = edge_range(&fine);
    println!("edges {shortest:.2e}–{longest:.2e} m");
    let none = vec![false; mesh.vertices()];
    for &n in levels {
        let start = Instant::now();
        let level = mesh::simplify(&mesh, n, &none, &file.display().to_string())?;
        let simplified = start.elapsed().as_secs_f64();
        let coarse = mesh::mesh_topology(&level.mesh);
        let up = Correlation::between(&coarse, &fine)?;
        let worst = up
            .entries()
            .iter()
            .zip(&fine.rest_positions)
            .map(|(e, p)| {
                let q = (0..3).map(|c| {
                    (0..3)
                        .map(|k| e.weights[k] * coarse.rest_positions[e.nodes[k] as usize][c])
                        .sum::<f64>()
                });
                q.zip(p).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt()
            })
            .fold(0.0, f64::max);
        let total = start.elapsed().as_secs_f64();
        let (shortest, longest) = edge_range(&coarse);
        println!(
            "level {n}v: {} vertices ({:.0} % of the reference), {} triangles, area {:.3} % of the reference, \
             edges {:.2e}–{:.2e} m, geometric error {:.2e} of the extent, reference vertices off its surface by ≤ {:.2e} m; \
             simplified in {:.1} ms, springs and correlation in {:.1} ms",
            level.mesh.vertices(),
            100.0 * level.mesh.vertices() as f64 / mesh.vertices() as f64,
            level.mesh.triangles.len(),
            100.0 * level.mesh.area() / mesh.area(),
            shortest,
            longest,
            level.error,
            worst,
            1e3 * simplified,
            1e3 * (total - simplified)
        );
    }
    Ok(())
}

/// The shortest and longest stretch spring (edge) of a mesh topology (m):
/// the shortest, with its vertices' masses, sets the stable step.
fn edge_range(topology: &lodcloth::sim::Topology) -> (f64, f64) {
    topology
        .groups
        .iter()
        .filter(|g| g.kind() == lodcloth::sim::SpringKind::Structural)
        .flat_map(|g| g.rest.iter().copied())
        .fold((f64::INFINITY, 0.0), |(lo, hi), l| (lo.min(l), hi.max(l)))
}

fn describe(file: &std::path::Path, mesh: &TriMesh) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &mesh.positions {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let border = mesh.border().iter().filter(|&&b| b).count();
    println!(
        "{}: {} vertices ({} on the border), {} triangles, area {:.6} m², bounds x {:.3}..{:.3} y {:.3}..{:.3} z {:.3}..{:.3} m",
        file.display(),
        mesh.vertices(),
        border,
        mesh.triangles.len(),
        mesh.area(),
        lo[0],
        hi[0],
        lo[1],
        hi[1],
        lo[2],
        hi[2]
    );
    println!(
        "material coordinates: {}",
        if mesh.uv_from_file {
            "the file's texture coordinates"
        } else {
            "the rest shape flattened onto its best-fit plane"
        }
    );
    if mesh.groups.is_empty() {
        println!("groups: none");
    }
    for (name, members) in &mesh.groups {
        println!("group '{name}': {} vertices", members.len());
    }
}
