//! OBJ (read with `tobj`): every object or group a vertex group.

use std::borrow::Cow;
use std::io::{BufRead, Read};
use std::path::Path;

use super::{format_err, io_err, Builder, MeshError};

/// Read an OBJ file: every object or group (`o`, `g`) a vertex group, all of
/// them one mesh. Materials are not read; polylines (`l`) and points are
/// ignored.
pub(super) fn read_obj(path: &Path) -> Result<Builder<'_>, MeshError> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    let text = check_obj(path, &bytes)?;
    let mut reader = LineReader {
        data: &text,
        pos: 0,
        line_start: 0,
    };
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // Materials are never loaded: a missing or broken MTL file is no concern
    // of a cloth.
    let (models, _materials) = tobj::load_obj_buf(&mut reader, &options, |_| Err(tobj::LoadError::GenericFailure))
        .map_err(|e| format_err(path, obj_error(&e, reader.line())))?;
    // With `single_index`, tobj gives a texture coordinate to each vertex
    // whose face corner names one: UVs only when all of them do.
    let with_uv = models
        .iter()
        .all(|m| m.mesh.texcoords.len() == m.mesh.positions.len() / 3 * 2);
    let mut mesh = Builder::new(path);
    for model in &models {
        let m = &model.mesh;
        let mut ids = Vec::with_capacity(m.positions.len() / 3);
        for (k, p) in m.positions.chunks_exact(3).enumerate() {
            let uv = if with_uv {
                m.texcoords.get(2 * k..2 * k + 2).map(|t| [t[0], t[1]])
            } else {
                None
            };
            ids.push(mesh.vertex([p[0], p[1], p[2]], uv)?);
        }
        for (t, tri) in m.indices.chunks_exact(3).enumerate() {
            let mut welded = [0u32; 3];
            for (c, &i) in tri.iter().enumerate() {
                welded[c] = *ids.get(i as usize).ok_or_else(|| {
                    format_err(
                        path,
                        format!(
                            "object `{}`, triangle {t}: vertex {i} out of range ({} vertices)",
                            model.name,
                            ids.len()
                        ),
                    )
                })?;
            }
            mesh.triangle(welded);
        }
        // tobj names what comes before any `o`/`g` line `unnamed_object`:
        // no group the file gave.
        if model.name != "unnamed_object" {
            mesh.group(&model.name, &ids);
        }
    }
    Ok(mesh)
}

/// Check every face of an OBJ file before tobj reads it (tobj reports a bad
/// index without saying where, and can overflow on some): each line valid
/// UTF-8, each face three or more corners `v`, `v/vt`, `v//vn` or `v/vt/vn`
/// whose indices name existing `v`, `vt`, `vn` lines. Returns the text with
/// polyline (`l`) lines blanked: tobj would take a polyline of three or more
/// points for a polygon.
fn check_obj<'b>(path: &Path, bytes: &'b [u8]) -> Result<Cow<'b, [u8]>, MeshError> {
    const KIND: [&str; 3] = ["vertex", "texture coordinate", "normal"];
    const KEYWORD: [&str; 3] = ["v", "vt", "vn"];
    let mut counts = [0usize; 3];
    // Each kind's positive indices where their running maximum grows, with
    // the line and face: the first face naming a line past the end of the
    // file is one of them (indices may name lines further down).
    let mut records: [Vec<(usize, usize, usize)>; 3] = Default::default();
    let mut max = [0usize; 3];
    let mut polylines = Vec::new();
    let mut face = 0usize;
    let mut start = 0usize;
    for (l, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let lineno = l + 1;
        let range = start..start + raw.len();
        start = range.end + 1;
        let line = std::str::from_utf8(raw).map_err(|e| {
            let good = e.valid_up_to();
            let column = std::str::from_utf8(&raw[..good]).map_or(0, |t| t.chars().count()) + 1;
            format_err(
                path,
                format!(
                    "line {lineno}, column {column}: not valid UTF-8 (byte 0x{:02x})",
                    raw[good]
                ),
            )
        })?;
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("l") => polylines.push(range),
            Some("f") => {
                let at = format!("line {lineno} (face {face})");
                let mut corners = 0usize;
                for word in words {
                    corners += 1;
                    let not_corner = || {
                        format_err(
                            path,
                            format!("{at}: `{word}` is not a face corner (v, v/vt, v//vn or v/vt/vn)"),
                        )
                    };
                    for (k, part) in word.split('/').enumerate() {
                        if k > 2 || (k == 0 && part.is_empty()) {
                            return Err(not_corner());
                        }
                        if part.is_empty() {
                            continue;
                        }
                        let x: isize = part.parse().map_err(|_| not_corner())?;
                        if x == 0 {
                            return Err(format_err(
                                path,
                                format!("{at}: {} index 0 (OBJ indices start at 1)", KIND[k]),
                            ));
                        }
                        if x < 0 {
                            if x.unsigned_abs() > counts[k] {
                                return Err(format_err(
                                    path,
                                    format!(
                                        "{at}: relative {} index {x} reaches before the first `{}` line ({} so far)",
                                        KIND[k], KEYWORD[k], counts[k]
                                    ),
                                ));
                            }
                        } else if x.unsigned_abs() > max[k] {
                            max[k] = x.unsigned_abs();
                            records[k].push((max[k], lineno, face));
                        }
                    }
                }
                if corners < 3 {
                    return Err(format_err(
                        path,
                        format!("{at}: {corners} corners (a face needs three or more)"),
                    ));
                }
                face += 1;
            }
            _ => {}
        }
    }
    let first_bad = (0..3)
        .filter_map(|k| {
            records[k]
                .iter()
                .find(|(x, ..)| *x > counts[k])
                .map(|&(x, lineno, face)| (lineno, face, k, x))
        })
        .min();
    if let Some((lineno, face, k, x)) = first_bad {
        return Err(format_err(
            path,
            format!(
                "line {lineno} (face {face}): {} {x} out of range (the file has {} `{}` lines)",
                KIND[k], counts[k], KEYWORD[k]
            ),
        ));
    }
    if polylines.is_empty() {
        return Ok(Cow::Borrowed(bytes));
    }
    // Blank, not remove: line numbers stay those of the file.
    let mut text = bytes.to_vec();
    for range in polylines {
        if let Some(line) = text.get_mut(range) {
            line.fill(b' ');
        }
    }
    Ok(Cow::Owned(text))
}

/// What tobj reported, where (the line it was reading).
fn obj_error(e: &tobj::LoadError, line: usize) -> String {
    use tobj::LoadError as E;
    match e {
        E::PositionParseError => format!("line {line}: a `v` line needs three numbers x y z"),
        E::ScalingByZeroError => format!("line {line}: a `v` line with weight w = 0"),
        E::ColorParseError => {
            format!("line {line}: a `v` line needs 3 (x y z), 4 (x y z w) or 6 (x y z r g b) numbers")
        }
        E::TexcoordParseError => format!("line {line}: a `vt` line needs two numbers u v"),
        E::NormalParseError => format!("line {line}: a `vn` line needs three numbers"),
        E::MaterialParseError => format!("line {line}: `usemtl` without a material name"),
        // Found only when an object ends: with checked faces, only colours
        // given on some `v` lines and not others.
        E::FaceColorOutOfBounds => "vertex colours are given on some `v` lines but not all".to_string(),
        E::FaceVertexOutOfBounds
        | E::FaceTexCoordOutOfBounds
        | E::FaceNormalOutOfBounds
        | E::InvalidPolygon
        | E::InvalidLoadOptionConfig => format!("OBJ: {e}"),
        _ => format!("line {line}: {e}"),
    }
}

/// An OBJ file's bytes as a [`BufRead`] that knows which line it handed out
/// last (tobj reads a line at a time and reports no line numbers).
struct LineReader<'b> {
    data: &'b [u8],
    pos: usize,
    /// Where the line read last starts.
    line_start: usize,
}

impl LineReader<'_> {
    /// The number (from 1) of the line read last.
    fn line(&self) -> usize {
        self.data[..self.line_start.min(self.data.len())]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1
    }
}

impl Read for LineReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let rest = &self.data[self.pos.min(self.data.len())..];
        let n = rest.len().min(buf.len());
        buf[..n].copy_from_slice(&rest[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl BufRead for LineReader<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        Ok(&self.data[self.pos.min(self.data.len())..])
    }

    fn consume(&mut self, amount: usize) {
        // `read_line` takes a whole line in one `consume`: what `fill_buf`
        // hands out is the rest of the file.
        if amount > 0 {
            self.line_start = self.pos;
        }
        self.pos = self.pos.saturating_add(amount).min(self.data.len());
    }
}
