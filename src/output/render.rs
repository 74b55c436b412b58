//! PNG renders: a cloth as shaded triangles with its pins, a point cloud
//! as shaded splats.

use std::path::Path;

use plotters::prelude::*;

use super::camera::{frame, normalize, project};
use super::OutputError;
use crate::sim::vec3::{cross, dot, sub};
use crate::sim::{State, Topology};

/// Render the cloth as shaded triangles seen obliquely from the front, pinned
/// nodes as red dots, to a PNG of `size × size` pixels.
pub fn render_png(
    path: &Path,
    topology: &Topology,
    state: &State,
    pinned: &[u32],
    size: u32,
) -> Result<(), OutputError> {
    let draw_err = |e: String| OutputError::Draw {
        path: path.display().to_string(),
        reason: e,
    };
    let n = topology.n_nodes;
    let pts: Vec<[f64; 3]> = (0..n).map(|k| state.position(k)).collect();
    let proj = project(&pts);
    let (cx, cy, span) =
        frame(std::slice::from_ref(&proj)).ok_or_else(|| draw_err("no finite node position to draw".into()))?;
    let px = |x: f64, y: f64| -> (i32, i32) {
        let s = f64::from(size);
        (
            ((x - cx) / span * s + 0.5 * s) as i32,
            ((cy - y) / span * s + 0.5 * s) as i32,
        )
    };
    let root = BitMapBackend::new(path, (size, size)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(e.to_string()))?;
    // Painter's algorithm: far triangles first.
    let mut order: Vec<usize> = (0..topology.triangles.len()).collect();
    let depth = |t: usize| topology.triangles[t].iter().map(|&k| proj[k as usize].2).sum::<f64>();
    order.sort_by(|&a, &b| depth(b).total_cmp(&depth(a)));
    let light = normalize([0.3, 0.8, 0.5]);
    for t in order {
        let [a, b, c] = topology.triangles[t].map(|k| pts[k as usize]);
        let nrm = normalize(cross(sub(b, a), sub(c, a)));
        let shade = 0.25 + 0.75 * dot(nrm, light).abs();
        let color = RGBColor((70.0 * shade) as u8, (120.0 * shade) as u8, (200.0 * shade) as u8);
        let poly: Vec<(i32, i32)> = topology.triangles[t]
            .iter()
            .map(|&k| px(proj[k as usize].0, proj[k as usize].1))
            .collect();
        root.draw(&Polygon::new(poly, color.filled()))
            .map_err(|e| draw_err(e.to_string()))?;
    }
    for &k in pinned {
        let (x, y, _) = proj[k as usize];
        root.draw(&Circle::new(px(x, y), 3, RED.filled()))
            .map_err(|e| draw_err(e.to_string()))?;
    }
    root.present().map_err(|e| draw_err(e.to_string()))?;
    Ok(())
}

/// Render a point cloud (z up, as the generated shapes) to a PNG: every
/// point a disc of radius `radius` (m, about the point spacing) shaded by its
/// normal, far points first; points facing away (the inside of an open
/// surface) in a warmer colour; the `highlight`ed ones (the simulation
/// points) marked in red.
pub fn render_points_png(
    path: &Path,
    positions: &[[f64; 3]],
    normals: &[[f64; 3]],
    highlight: &[u32],
    radius: f64,
    size: u32,
) -> Result<(), OutputError> {
    let draw_err = |e: String| OutputError::Draw {
        path: path.display().to_string(),
        reason: e,
    };
    // z up → the renderer's y up (a rotation about x).
    let yup = |p: &[f64; 3]| [p[0], p[2], -p[1]];
    let pts: Vec<[f64; 3]> = positions.iter().map(yup).collect();
    let nrm: Vec<[f64; 3]> = normals.iter().map(yup).collect();
    let proj = project(&pts);
    let nproj = project(&nrm);
    let (cx, cy, span) =
        frame(std::slice::from_ref(&proj)).ok_or_else(|| draw_err("no finite point to draw".into()))?;
    let s = f64::from(size);
    let px = |x: f64, y: f64| -> (i32, i32) {
        (
            ((x - cx) / span * s + 0.5 * s) as i32,
            ((cy - y) / span * s + 0.5 * s) as i32,
        )
    };
    let r_px = (radius / span * s).clamp(1.0, 12.0) as i32;
    let root = BitMapBackend::new(path, (size, size)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(e.to_string()))?;
    let mut order: Vec<usize> = (0..pts.len())
        .filter(|&k| proj[k].0.is_finite() && proj[k].1.is_finite())
        .collect();
    order.sort_by(|&a, &b| proj[b].2.total_cmp(&proj[a].2));
    let light = normalize([0.3, 0.8, 0.5]);
    for k in order {
        let n = nrm.get(k).copied().unwrap_or([0.0, 1.0, 0.0]);
        let away = nproj.get(k).is_some_and(|p| p.2 > 0.0);
        let shade = 0.35 + 0.65 * dot(n, light).abs();
        let color = if away {
            RGBColor((200.0 * shade) as u8, (140.0 * shade) as u8, (80.0 * shade) as u8)
        } else {
            RGBColor((80.0 * shade) as u8, (140.0 * shade) as u8, (230.0 * shade) as u8)
        };
        root.draw(&Circle::new(px(proj[k].0, proj[k].1), r_px, color.filled()))
            .map_err(|e| draw_err(e.to_string()))?;
    }
    for &k in highlight {
        let (x, y, z) = proj[k as usize];
        // Only the simulation points on the visible side.
        if nproj.get(k as usize).is_some_and(|p| p.2 > 0.0) && z.is_finite() {
            continue;
        }
        root.draw(&Circle::new(px(x, y), 2, RED.filled()))
            .map_err(|e| draw_err(e.to_string()))?;
    }
    root.present().map_err(|e| draw_err(e.to_string()))?;
    Ok(())
}
