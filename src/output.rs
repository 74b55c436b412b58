//! Files a run leaves behind: the binary trajectory (written and read back),
//! the per-frame CSV report, a PNG render of a cloth and SVG charts.
//!
//! # Trajectory format (`.lct`, version 1, all little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `LCTRAJ01` |
//! | 8 | 4 | u32 version = 1 |
//! | 12 | 4 | u32 flags: bit 0 = values are f64 (else f32); bit 1 = velocities stored |
//! | 16 | 4 | u32 nx (0 when the cloth is not a grid) |
//! | 20 | 4 | u32 ny |
//! | 24 | 8 | u64 number of nodes n |
//! | 32 | 8 | f64 dt (s) |
//! | 40 | 4 | u32 steps between frames |
//! | 44 | 4 | u32 reserved (0) |
//! | 48 | 8 | u64 number of frames, written when the file is finished; 0 if the writer stopped early (readers then count whole frames by size) |
//!
//! Then frames of `8 + 8 + 3n·s (+ 3n·s)` bytes: u64 step, f64 time, the
//! positions node by node (x, y, z), and with bit 1 the velocities likewise;
//! `s` is 4 or 8 bytes per value.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::Path;

use plotters::prelude::*;

use crate::sim::vec3::{cross, dot, sub};
use crate::sim::{SpringKind, State, StepReport, Topology};

/// File magic of trajectory files.
pub const TRAJECTORY_MAGIC: &[u8; 8] = b"LCTRAJ01";
const HEADER_LEN: u64 = 56;

/// Errors from reading or writing output files.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{path}: not a trajectory file ({reason})")]
    Format { path: String, reason: String },
    #[error("{path}: cannot draw: {reason}")]
    Draw { path: String, reason: String },
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Value precision in a trajectory file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    F32,
    F64,
}

/// Header of a trajectory file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectoryHeader {
    pub precision: Precision,
    pub velocities: bool,
    pub nx: u32,
    pub ny: u32,
    pub n_nodes: u64,
    pub dt: f64,
    pub frame_every: u32,
    /// Frames in the file (counted from its size when the writer stopped early).
    pub n_frames: u64,
}

impl TrajectoryHeader {
    fn value_size(&self) -> u64 {
        match self.precision {
            Precision::F32 => 4,
            Precision::F64 => 8,
        }
    }

    /// Bytes per frame.
    pub fn frame_len(&self) -> u64 {
        let per = 3 * self.n_nodes * self.value_size();
        16 + per * if self.velocities { 2 } else { 1 }
    }
}

/// Streams frames to a trajectory file.
pub struct TrajectoryWriter {
    out: BufWriter<File>,
    header: TrajectoryHeader,
    path: String,
    buf: Vec<u8>,
}

impl TrajectoryWriter {
    /// Create `path` for a cloth of `n_nodes` nodes (`grid` = (nx, ny) when a grid).
    pub fn create(
        path: &Path,
        n_nodes: usize,
        grid: Option<(usize, usize)>,
        dt: f64,
        frame_every: u32,
        precision: Precision,
        velocities: bool,
    ) -> Result<TrajectoryWriter, OutputError> {
        let file = File::create(path).map_err(io_err(path))?;
        let (nx, ny) = grid.unwrap_or((0, 0));
        let header = TrajectoryHeader {
            precision,
            velocities,
            nx: nx as u32,
            ny: ny as u32,
            n_nodes: n_nodes as u64,
            dt,
            frame_every,
            n_frames: 0,
        };
        let mut w = TrajectoryWriter {
            out: BufWriter::new(file),
            header,
            path: path.display().to_string(),
            buf: Vec::with_capacity(header.frame_len() as usize),
        };
        let mut h = Vec::with_capacity(HEADER_LEN as usize);
        h.extend_from_slice(TRAJECTORY_MAGIC);
        h.extend_from_slice(&1u32.to_le_bytes());
        let flags = u32::from(precision == Precision::F64) | (u32::from(velocities) << 1);
        h.extend_from_slice(&flags.to_le_bytes());
        h.extend_from_slice(&header.nx.to_le_bytes());
        h.extend_from_slice(&header.ny.to_le_bytes());
        h.extend_from_slice(&header.n_nodes.to_le_bytes());
        h.extend_from_slice(&dt.to_le_bytes());
        h.extend_from_slice(&frame_every.to_le_bytes());
        h.extend_from_slice(&0u32.to_le_bytes());
        h.extend_from_slice(&0u64.to_le_bytes());
        debug_assert_eq!(h.len() as u64, HEADER_LEN);
        w.out.write_all(&h).map_err(|source| OutputError::Io {
            path: w.path.clone(),
            source,
        })?;
        Ok(w)
    }

    /// Append the state as a frame.
    pub fn write(&mut self, state: &State) -> Result<(), OutputError> {
        let n = state.n_nodes();
        self.buf.clear();
        self.buf.extend_from_slice(&state.step.to_le_bytes());
        self.buf.extend_from_slice(&state.time.to_le_bytes());
        let mut put = |v: &[f64]| {
            for k in 0..n {
                for c in 0..3 {
                    let x = v[c * n + k];
                    match self.header.precision {
                        Precision::F32 => self.buf.extend_from_slice(&(x as f32).to_le_bytes()),
                        Precision::F64 => self.buf.extend_from_slice(&x.to_le_bytes()),
                    }
                }
            }
        };
        put(&state.pos);
        if self.header.velocities {
            put(&state.vel);
        }
        self.out.write_all(&self.buf).map_err(|source| OutputError::Io {
            path: self.path.clone(),
            source,
        })?;
        self.header.n_frames += 1;
        Ok(())
    }

    /// Flush and record the frame count in the header.
    pub fn finish(mut self) -> Result<TrajectoryHeader, OutputError> {
        let path = self.path.clone();
        let e = |source| OutputError::Io {
            path: path.clone(),
            source,
        };
        self.out.flush().map_err(e)?;
        let mut file = self.out.into_inner().map_err(|e2| e(e2.into_error()))?;
        file.seek(SeekFrom::Start(48)).map_err(e)?;
        file.write_all(&self.header.n_frames.to_le_bytes()).map_err(e)?;
        file.sync_all().map_err(e)?;
        Ok(self.header)
    }
}

/// One frame read back: step, time, positions (and velocities) as `[x, y, z]` per node.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub step: u64,
    pub time: f64,
    pub positions: Vec<[f64; 3]>,
    pub velocities: Option<Vec<[f64; 3]>>,
}

/// Reads a trajectory file frame by frame.
pub struct TrajectoryReader {
    input: BufReader<File>,
    header: TrajectoryHeader,
    next: u64,
    path: String,
}

impl TrajectoryReader {
    /// Open and check a trajectory file.
    pub fn open(path: &Path) -> Result<TrajectoryReader, OutputError> {
        let file = File::open(path).map_err(io_err(path))?;
        let size = file.metadata().map_err(io_err(path))?.len();
        let mut input = BufReader::new(file);
        let bad = |reason: String| OutputError::Format {
            path: path.display().to_string(),
            reason,
        };
        if size < HEADER_LEN {
            return Err(bad(format!(
                "{size} bytes is shorter than the {HEADER_LEN}-byte header"
            )));
        }
        let mut h = [0u8; HEADER_LEN as usize];
        input.read_exact(&mut h).map_err(io_err(path))?;
        if &h[0..8] != TRAJECTORY_MAGIC {
            return Err(bad("wrong magic bytes".into()));
        }
        let u32_at = |o: usize| u32::from_le_bytes(h[o..o + 4].try_into().expect("4 bytes"));
        let u64_at = |o: usize| u64::from_le_bytes(h[o..o + 8].try_into().expect("8 bytes"));
        let version = u32_at(8);
        if version != 1 {
            return Err(bad(format!("version {version} is not supported (expected 1)")));
        }
        let flags = u32_at(12);
        if flags & !3 != 0 {
            return Err(bad(format!("unknown flags {flags:#x}")));
        }
        let mut header = TrajectoryHeader {
            precision: if flags & 1 != 0 { Precision::F64 } else { Precision::F32 },
            velocities: flags & 2 != 0,
            nx: u32_at(16),
            ny: u32_at(20),
            n_nodes: u64_at(24),
            dt: f64::from_le_bytes(h[32..40].try_into().expect("8 bytes")),
            frame_every: u32_at(40),
            n_frames: u64_at(48),
        };
        if header.n_nodes == 0 || header.n_nodes > 1 << 32 {
            return Err(bad(format!("implausible node count {}", header.n_nodes)));
        }
        if header.nx != 0 && u64::from(header.nx) * u64::from(header.ny) != header.n_nodes {
            return Err(bad(format!(
                "grid {}×{} does not have {} nodes",
                header.nx, header.ny, header.n_nodes
            )));
        }
        let whole = (size - HEADER_LEN) / header.frame_len();
        if header.n_frames == 0 {
            header.n_frames = whole; // the writer stopped early: keep every complete frame
        } else if header.n_frames > whole {
            return Err(bad(format!(
                "header says {} frames, the file holds {whole}",
                header.n_frames
            )));
        }
        Ok(TrajectoryReader {
            input,
            header,
            next: 0,
            path: path.display().to_string(),
        })
    }

    /// The header.
    pub fn header(&self) -> &TrajectoryHeader {
        &self.header
    }

    /// Next frame, or `None` after the last.
    pub fn next_frame(&mut self) -> Result<Option<Frame>, OutputError> {
        if self.next >= self.header.n_frames {
            return Ok(None);
        }
        let mut buf = vec![0u8; self.header.frame_len() as usize];
        self.input.read_exact(&mut buf).map_err(|source| OutputError::Io {
            path: self.path.clone(),
            source,
        })?;
        self.next += 1;
        let n = self.header.n_nodes as usize;
        let s = self.header.value_size() as usize;
        let value = |o: usize| match self.header.precision {
            Precision::F32 => f64::from(f32::from_le_bytes(buf[o..o + 4].try_into().expect("4 bytes"))),
            Precision::F64 => f64::from_le_bytes(buf[o..o + 8].try_into().expect("8 bytes")),
        };
        let block = |start: usize| -> Vec<[f64; 3]> {
            (0..n)
                .map(|k| {
                    let o = start + 3 * k * s;
                    [value(o), value(o + s), value(o + 2 * s)]
                })
                .collect()
        };
        Ok(Some(Frame {
            step: u64::from_le_bytes(buf[0..8].try_into().expect("8 bytes")),
            time: f64::from_le_bytes(buf[8..16].try_into().expect("8 bytes")),
            positions: block(16),
            velocities: self.header.velocities.then(|| block(16 + 3 * n * s)),
        }))
    }
}

/// Header line of the per-frame CSV report.
pub const REPORT_CSV_HEADER: &str = "step,time_s,kinetic_j,elastic_j,gravity_j,total_j,max_strain_structural,max_strain_shear,max_strain_bend,finite,solver_iterations,solver_residual,strain_iterations";

/// One CSV line for a report (matches [`REPORT_CSV_HEADER`]).
pub fn report_csv_line(r: &StepReport) -> String {
    format!(
        "{},{:.6},{:.9e},{:.9e},{:.9e},{:.9e},{:.6e},{:.6e},{:.6e},{},{},{:.3e},{}",
        r.step,
        r.time,
        r.kinetic_energy,
        r.elastic_energy,
        r.gravity_energy,
        r.total_energy(),
        r.max_strain[SpringKind::Structural.index()],
        r.max_strain[SpringKind::Shear.index()],
        r.max_strain[SpringKind::Bend.index()],
        r.finite,
        r.solver_iterations,
        r.solver_residual,
        r.strain_iterations
    )
}

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

/// A named series for [`line_chart_svg`].
pub struct Series<'a> {
    pub name: &'a str,
    pub points: Vec<(f64, f64)>,
    /// Draw markers only (measurements) instead of a line (predictions).
    pub markers: bool,
    pub color: RGBColor,
}

/// A chart of several series to an SVG file. Log axes when requested
/// (non-positive values are then skipped).
pub fn line_chart_svg(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    log_x: bool,
    log_y: bool,
) -> Result<(), OutputError> {
    let draw_err = |e: String| OutputError::Draw {
        path: path.display().to_string(),
        reason: e,
    };
    let keep = |(x, y): &(f64, f64)| x.is_finite() && y.is_finite() && (!log_x || *x > 0.0) && (!log_y || *y > 0.0);
    let all: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.points.iter().copied().filter(keep))
        .collect();
    if all.is_empty() {
        return Err(draw_err("no finite point to plot".into()));
    }
    let range = |v: Vec<f64>, log: bool| {
        let (lo, hi) = v.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        if log {
            (lo / 1.5, hi * 1.5)
        } else {
            let pad = ((hi - lo) * 0.05).max(1e-12);
            (lo - pad, hi + pad)
        }
    };
    let (x0, x1) = range(all.iter().map(|p| p.0).collect(), log_x);
    let (y0, y1) = range(all.iter().map(|p| p.1).collect(), log_y);
    let root = SVGBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(e.to_string()))?;
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(y_label)
                .draw()
                .map_err(|e| draw_err(e.to_string()))?;
            for s in series {
                let pts: Vec<(f64, f64)> = s.points.iter().copied().filter(keep).collect();
                let color = s.color;
                if s.markers {
                    chart
                        .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
                        .map_err(|e| draw_err(e.to_string()))?
                        .label(s.name)
                        .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
                } else {
                    chart
                        .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                        .map_err(|e| draw_err(e.to_string()))?
                        .label(s.name)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
                }
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| draw_err(e.to_string()))?;
        }};
    }
    fn builder<'a, 'b>(
        root: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
        title: &str,
    ) -> ChartBuilder<'a, 'b, SVGBackend<'b>> {
        let mut b = ChartBuilder::on(root);
        b.caption(title, ("sans-serif", 22))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(80);
        b
    }
    match (log_x, log_y) {
        (true, true) => draw!(builder(&root, title)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| draw_err(e.to_string()))?),
        (true, false) => draw!(builder(&root, title)
            .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
            .map_err(|e| draw_err(e.to_string()))?),
        (false, true) => draw!(builder(&root, title)
            .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
            .map_err(|e| draw_err(e.to_string()))?),
        (false, false) => draw!(builder(&root, title)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| draw_err(e.to_string()))?),
    }
    root.present().map_err(|e| draw_err(e.to_string()))?;
    Ok(())
}

/// Colours for series, in order.
pub const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Orthographic camera of every cloth picture: azimuth 35° about y,
/// elevation 20°. Returns (right, up, depth) per point.
fn project(points: &[[f64; 3]]) -> Vec<(f64, f64, f64)> {
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
fn frame(projected: &[Vec<(f64, f64, f64)>]) -> Option<(f64, f64, f64)> {
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

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    if l > 0.0 {
        a.map(|x| x / l)
    } else {
        a
    }
}

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
