//! Point-cloud files: PLY (ASCII or binary, any scalar type, with or without
//! normals; read with the `ply-rs-bw` crate) and XYZ text (`x y z` or
//! `x y z nx ny nz` per line, `#` comments). Every failure names the file
//! and the line, vertex or property at fault.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Addable, ElementDef, Encoding, Ply, PropertyDef, PropertyType, ScalarType};
use ply_rs_bw::writer::Writer;

use super::PointCloud;
use crate::sim::vec3::{normalize, V3};

/// A point-cloud file that could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum PointsIoError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system reported.
        #[source]
        source: std::io::Error,
    },
    /// The file's contents are not a valid cloud of its format.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong and where.
        message: String,
    },
    /// The extension names no format this module reads.
    #[error("{path}: unknown point-cloud format (expected .ply, .xyz, .txt or .pts)")]
    Format {
        /// The file.
        path: PathBuf,
    },
}

fn invalid(path: &Path, message: impl Into<String>) -> PointsIoError {
    PointsIoError::Invalid {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> PointsIoError + '_ {
    move |source| PointsIoError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Read a cloud, choosing the format by extension.
pub fn read(path: &Path) -> Result<PointCloud, PointsIoError> {
    match extension(path).as_deref() {
        Some("ply") => read_ply(path),
        Some("xyz" | "txt" | "pts") => read_xyz(path),
        _ => Err(PointsIoError::Format {
            path: path.to_path_buf(),
        }),
    }
}

/// Write a cloud, choosing the format by extension (PLY is written binary
/// little-endian).
pub fn write(path: &Path, cloud: &PointCloud) -> Result<(), PointsIoError> {
    match extension(path).as_deref() {
        Some("ply") => write_ply(path, cloud, Encoding::BinaryLittleEndian),
        Some("xyz" | "txt" | "pts") => write_xyz(path, cloud),
        _ => Err(PointsIoError::Format {
            path: path.to_path_buf(),
        }),
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase())
}

/// The PLY vertex properties a cloud keeps, in slot order.
const NAMES: [&str; 6] = ["x", "y", "z", "nx", "ny", "nz"];

/// Marks [`NAMES`] for [`crate::ply::Scalars`].
#[derive(Debug, Clone, Copy, Default)]
struct CloudVertex;

impl crate::ply::Names for CloudVertex {
    const NAMES: &'static [&'static str] = &NAMES;
}

/// One PLY vertex as read or written.
type Vertex = crate::ply::Scalars<CloudVertex>;

/// The unit vector along a finite file normal; None when it is zero. Scaled
/// by its largest component first, so that neither a huge normal (whose
/// length overflows) nor a subnormal one (whose length underflows) is taken
/// for zero.
fn unit_normal(n: V3) -> Option<V3> {
    let largest = n.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
    if !(largest > 0.0 && largest.is_finite()) {
        return None;
    }
    normalize(n.map(|x| x / largest))
}

/// Read a PLY file's `vertex` element: `x y z` required, `nx ny nz` optional
/// (all three or none).
pub fn read_ply(path: &Path) -> Result<PointCloud, PointsIoError> {
    let file = std::fs::File::open(path).map_err(io_err(path))?;
    let mut reader = Reader::new(BufReader::new(file));
    let parser = Parser::<Vertex>::new();
    let header = crate::ply::read_header::<Vertex, _>(&mut reader).map_err(|m| invalid(path, m))?;
    let Some(vertex_def) = header.elements.get("vertex") else {
        return Err(invalid(path, "PLY file has no `vertex` element"));
    };
    let props = &vertex_def.properties;
    crate::ply::check_xyz(props).map_err(|m| invalid(path, m))?;
    let normal_props = ["nx", "ny", "nz"].iter().filter(|n| props.contains_key(**n)).count();
    if normal_props != 0 && normal_props != 3 {
        return Err(invalid(path, "PLY vertex has some but not all of nx, ny, nz"));
    }
    if vertex_def.count == 0 {
        return Err(invalid(
            path,
            "PLY vertex element is empty (`element vertex 0`): no points",
        ));
    }
    let mut vertices = Vec::new();
    for (name, def) in &header.elements {
        if name == "vertex" {
            vertices = parser
                .read_payload_for_element(&mut reader, def, &header)
                .map_err(|e| invalid(path, format!("PLY vertex data: {e}")))?;
            break;
        }
        // Elements before the vertices are read and dropped.
        Parser::<ply_rs_bw::ply::DefaultElement>::new()
            .read_payload_for_element(&mut reader, def, &header)
            .map_err(|e| invalid(path, format!("PLY element `{name}`: {e}")))?;
    }
    let with_normals = normal_props == 3;
    let mut positions = Vec::with_capacity(vertices.len());
    let mut normals = Vec::with_capacity(if with_normals { vertices.len() } else { 0 });
    for (i, v) in vertices.iter().enumerate() {
        if let Some(k) = v.v.iter().position(|x| !x.is_finite()) {
            return Err(invalid(path, format!("PLY vertex {i}: {} is not finite", NAMES[k])));
        }
        positions.push([v.v[0], v.v[1], v.v[2]]);
        if with_normals {
            let n = unit_normal([v.v[3], v.v[4], v.v[5]])
                .ok_or_else(|| invalid(path, format!("PLY vertex {i}: normal (nx, ny, nz) is zero")))?;
            normals.push(n);
        }
    }
    Ok(PointCloud {
        positions,
        normals: with_normals.then_some(normals),
    })
}

/// Write a PLY file (`float` coordinates, normals when the cloud has them).
pub fn write_ply(path: &Path, cloud: &PointCloud, encoding: Encoding) -> Result<(), PointsIoError> {
    let mut ply = Ply::<Vertex>::new();
    ply.header.encoding = encoding;
    ply.header.comments.push("lodcloth point cloud".to_string());
    let mut def = ElementDef::new("vertex".to_string());
    let count = if cloud.normals.is_some() { 6 } else { 3 };
    for name in &NAMES[..count] {
        def.properties.add(PropertyDef::new(
            name.to_string(),
            PropertyType::Scalar(ScalarType::Float),
        ));
    }
    ply.header.elements.add(def);
    let vertices = cloud
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let n = cloud.normals.as_ref().map_or([0.0; 3], |n| n[i]);
            Vertex::of(&[p[0], p[1], p[2], n[0], n[1], n[2]])
        })
        .collect();
    ply.payload.insert("vertex".to_string(), vertices);
    let file = std::fs::File::create(path).map_err(io_err(path))?;
    let mut out = std::io::BufWriter::new(file);
    Writer::new().write_ply(&mut out, &mut ply).map_err(io_err(path))?;
    out.flush().map_err(io_err(path))
}

/// Read XYZ text: 3 or 6 numbers per line (the same count on every line).
pub fn read_xyz(path: &Path) -> Result<PointCloud, PointsIoError> {
    let file = std::fs::File::open(path).map_err(io_err(path))?;
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut width = None;
    for (l, line) in BufReader::new(file).split(b'\n').enumerate() {
        let line = line.map_err(io_err(path))?;
        let lineno = l + 1;
        let line = std::str::from_utf8(&line).map_err(|e| {
            let good = e.valid_up_to();
            let column = std::str::from_utf8(&line[..good]).map_or(0, |t| t.chars().count()) + 1;
            invalid(
                path,
                format!(
                    "line {lineno}, column {column}: not valid UTF-8 (byte 0x{:02x})",
                    line[good]
                ),
            )
        })?;
        let text = line.split('#').next().unwrap_or("").trim();
        if text.is_empty() {
            continue;
        }
        let mut v = [0.0; 6];
        let mut k = 0;
        for field in text
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|f| !f.is_empty())
        {
            if k == 6 {
                return Err(invalid(path, format!("line {lineno}: more than 6 numbers")));
            }
            v[k] = field
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| invalid(path, format!("line {lineno}: `{field}` is not a finite number")))?;
            k += 1;
        }
        if k != 3 && k != 6 {
            return Err(invalid(
                path,
                format!("line {lineno}: expected 3 (x y z) or 6 (x y z nx ny nz) numbers, found {k}"),
            ));
        }
        match width {
            None => width = Some(k),
            Some(w) if w != k => {
                return Err(invalid(
                    path,
                    format!("line {lineno}: {k} numbers, but earlier lines have {w}"),
                ))
            }
            _ => {}
        }
        positions.push([v[0], v[1], v[2]]);
        if k == 6 {
            let n = unit_normal([v[3], v[4], v[5]])
                .ok_or_else(|| invalid(path, format!("line {lineno}: normal (nx, ny, nz) is zero")))?;
            normals.push(n);
        }
    }
    if positions.is_empty() {
        return Err(invalid(path, "no points (every line empty or a comment)"));
    }
    Ok(PointCloud {
        positions,
        normals: (width == Some(6)).then_some(normals),
    })
}

/// Write XYZ text, with normals when the cloud has them.
pub fn write_xyz(path: &Path, cloud: &PointCloud) -> Result<(), PointsIoError> {
    let file = std::fs::File::create(path).map_err(io_err(path))?;
    let mut out = std::io::BufWriter::new(file);
    for (i, p) in cloud.positions.iter().enumerate() {
        match &cloud.normals {
            Some(n) => writeln!(out, "{} {} {} {} {} {}", p[0], p[1], p[2], n[i][0], n[i][1], n[i][2]),
            None => writeln!(out, "{} {} {}", p[0], p[1], p[2]),
        }
        .map_err(io_err(path))?;
    }
    out.flush().map_err(io_err(path))
}
