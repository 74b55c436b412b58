//! Error maps: cloths side by side, coloured by per-node error, as in the
//! paper's figures.

use std::path::Path;

use plotters::prelude::*;

use lodcloth::output::camera::{frame, normalize, project};
use lodcloth::output::OutputError;
use lodcloth_core::sim::vec3::{cross, dot, sub};
use lodcloth_core::sim::Topology;

/// One cloth panel of [`error_map_svg`].
pub struct ClothPanel<'a> {
    pub title: String,
    pub topology: &'a Topology,
    /// Positions, SoA `[x…, y…, z…]`.
    pub pos: &'a [f64],
    /// Per-node values coloured blue (0) → red (`max_value`); `None` draws
    /// the cloth in a neutral shaded grey-blue (the reference).
    pub values: Option<&'a [f64]>,
}

/// Blue → cyan → green → yellow → red, as in the paper's error maps.
pub fn heat_color(x: f64) -> RGBColor {
    let x = if x.is_finite() { x.clamp(0.0, 1.0) } else { 1.0 };
    let stops = [(0, 0, 255), (0, 255, 255), (0, 255, 0), (255, 255, 0), (255, 0, 0)];
    let f = x * 4.0;
    let i = (f.floor() as usize).min(3);
    let t = f - i as f64;
    let lerp = |a: u8, b: u8| (f64::from(a) + t * (f64::from(b) - f64::from(a))).round() as u8;
    let (a, b) = (stops[i], stops[i + 1]);
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// Cloths side by side in one SVG, seen by the same camera at the same
/// scale, each coloured by its per-node values, with a labelled colour bar
/// from 0 to `max_value` (shown as a percentage).
pub fn error_map_svg(
    path: &Path,
    title: &str,
    panels: &[ClothPanel<'_>],
    max_value: f64,
    panel_size: u32,
) -> Result<(), OutputError> {
    let draw_err = |e: String| OutputError::Draw {
        path: path.display().to_string(),
        reason: e,
    };
    let projected: Vec<Vec<(f64, f64, f64)>> = panels
        .iter()
        .map(|p| {
            let n = p.topology.n_nodes;
            project(
                &(0..n)
                    .map(|k| [p.pos[k], p.pos[n + k], p.pos[2 * n + k]])
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    let (cx, cy, span) = frame(&projected).ok_or_else(|| draw_err("no finite node position to draw".into()))?;
    let s = f64::from(panel_size);
    let header = 40;
    let bar = 70;
    let width = panel_size * panels.len() as u32 + bar;
    let root = SVGBackend::new(path, (width, panel_size + header)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(e.to_string()))?;
    root.draw(&Text::new(title.to_string(), (10, 8), ("sans-serif", 18)))
        .map_err(|e| draw_err(e.to_string()))?;
    let light = normalize([0.3, 0.8, 0.5]);
    for (pi, (panel, proj)) in panels.iter().zip(&projected).enumerate() {
        let ox = pi as f64 * s;
        let px = |x: f64, y: f64| -> (i32, i32) {
            (
                (ox + (x - cx) / span * s + 0.5 * s) as i32,
                (f64::from(header) + (cy - y) / span * s + 0.5 * s) as i32,
            )
        };
        let topo = panel.topology;
        let n = topo.n_nodes;
        let pt = |k: u32| {
            let k = k as usize;
            [panel.pos[k], panel.pos[n + k], panel.pos[2 * n + k]]
        };
        let mut order: Vec<usize> = (0..topo.triangles.len()).collect();
        let depth = |t: usize| topo.triangles[t].iter().map(|&k| proj[k as usize].2).sum::<f64>();
        order.sort_by(|&a, &b| depth(b).total_cmp(&depth(a)));
        for t in order {
            let tri = topo.triangles[t];
            let [a, b, c] = tri.map(pt);
            let nrm = normalize(cross(sub(b, a), sub(c, a)));
            let shade = 0.55 + 0.45 * dot(nrm, light).abs();
            let color = match panel.values {
                Some(v) => {
                    let mean = tri.iter().map(|&k| v[k as usize]).sum::<f64>() / 3.0;
                    let c = heat_color(mean / max_value);
                    RGBColor(
                        (f64::from(c.0) * shade) as u8,
                        (f64::from(c.1) * shade) as u8,
                        (f64::from(c.2) * shade) as u8,
                    )
                }
                None => RGBColor((150.0 * shade) as u8, (170.0 * shade) as u8, (200.0 * shade) as u8),
            };
            let poly: Vec<(i32, i32)> = tri
                .iter()
                .map(|&k| px(proj[k as usize].0, proj[k as usize].1))
                .collect();
            root.draw(&Polygon::new(poly, color.filled()))
                .map_err(|e| draw_err(e.to_string()))?;
        }
        root.draw(&Text::new(
            panel.title.clone(),
            (ox as i32 + 10, header as i32 + 4),
            ("sans-serif", 15),
        ))
        .map_err(|e| draw_err(e.to_string()))?;
    }
    // Colour bar.
    let bx = (panel_size * panels.len() as u32) as i32 + 10;
    let (top, bottom) = (header as i32 + 30, (panel_size + header) as i32 - 30);
    let steps = 64;
    for i in 0..steps {
        let y = bottom - (i + 1) * (bottom - top) / steps;
        let h = (bottom - top) / steps + 1;
        root.draw(&Rectangle::new(
            [(bx, y), (bx + 18, y + h)],
            heat_color((f64::from(i) + 0.5) / f64::from(steps)).filled(),
        ))
        .map_err(|e| draw_err(e.to_string()))?;
    }
    for (frac, y) in [(0.0, bottom), (0.5, (top + bottom) / 2), (1.0, top)] {
        root.draw(&Text::new(
            format!("{:.1}%", 100.0 * frac * max_value),
            (bx + 21, y - 6),
            ("sans-serif", 12),
        ))
        .map_err(|e| draw_err(e.to_string()))?;
    }
    root.present().map_err(|e| draw_err(e.to_string()))?;
    Ok(())
}
