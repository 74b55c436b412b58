//! Reading cloth meshes: Wavefront OBJ (read with `tobj`), PLY (ASCII or
//! binary, read with `ply-rs-bw`) and glTF 2.0 (`.gltf` with embedded or
//! external buffers, `.glb`; read with `gltf`, buffers resolved here).
//!
//! Every reader welds vertices with bit-identical positions into one (files
//! split vertices at UV seams and normal creases; a cloth must not tear
//! there), keeps the first texture coordinate seen for a welded vertex, drops
//! the triangles that welding collapses, and ends in [`TriMesh::validated`].
//! Every failure names the file and the line, face, accessor or buffer at
//! fault.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType};

use super::{MeshError, TriMesh};

/// The extensions [`load`] reads, for error messages.
const EXTENSIONS: &str = ".obj, .ply, .gltf or .glb";

/// Read a cloth mesh: `.obj`, `.ply`, `.gltf` or `.glb` (by extension,
/// case-insensitive).
///
/// Vertices at bit-identical positions become one vertex (the first UV seen
/// is kept); triangles that this collapses are dropped. Vertex groups: OBJ
/// objects and groups (`o`, `g`), glTF nodes with a mesh; PLY has none. The
/// mesh has UVs when every vertex in the file has one; material v runs
/// down the texture (0 at its top edge, as a grid's row 0), so `1 − v` of
/// OBJ and PLY and glTF's own v. Polygons are fan-triangulated.
pub fn load(path: &Path) -> Result<TriMesh, MeshError> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    let mesh = match ext.as_deref() {
        Some("obj") => read_obj(path)?,
        Some("ply") => read_ply(path)?,
        Some("gltf" | "glb") => read_gltf(path)?,
        Some(other) => {
            return Err(format_err(
                path,
                format!("unknown mesh format `.{other}` (expected {EXTENSIONS})"),
            ))
        }
        None => {
            return Err(format_err(
                path,
                format!("no extension: cannot tell the mesh format (expected {EXTENSIONS})"),
            ))
        }
    };
    mesh.finish()
}

fn format_err(path: &Path, message: impl Into<String>) -> MeshError {
    MeshError::Format {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> MeshError + '_ {
    move |source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A mesh being read: welded vertices, triangles and vertex groups.
struct Builder<'a> {
    path: &'a Path,
    positions: Vec<[f64; 3]>,
    /// The first texture coordinate seen for each vertex (zero when none).
    uv: Vec<[f64; 2]>,
    /// Whether every vertex added so far came with a texture coordinate.
    all_uv: bool,
    /// Welding: the vertex at each position, keyed on the f64 bit patterns.
    index: HashMap<[u64; 3], u32>,
    triangles: Vec<[u32; 3]>,
    groups: BTreeMap<String, Vec<u32>>,
    /// Triangles dropped because welding made two of their corners one.
    collapsed: usize,
}

impl<'a> Builder<'a> {
    fn new(path: &'a Path) -> Self {
        Builder {
            path,
            positions: Vec::new(),
            uv: Vec::new(),
            all_uv: true,
            index: HashMap::new(),
            triangles: Vec::new(),
            groups: BTreeMap::new(),
            collapsed: 0,
        }
    }

    /// The vertex at `p`: an earlier one at the bit-identical position, or a
    /// new one. `-0.0` and `0.0` are the same position.
    fn vertex(&mut self, p: [f64; 3], uv: Option<[f64; 2]>) -> Result<u32, MeshError> {
        self.all_uv &= uv.is_some();
        let key = p.map(|x| (x + 0.0).to_bits());
        if let Some(&i) = self.index.get(&key) {
            return Ok(i);
        }
        let i = u32::try_from(self.positions.len())
            .ok()
            .filter(|&i| i < u32::MAX)
            .ok_or_else(|| format_err(self.path, format!("more than {} distinct vertices", u32::MAX)))?;
        self.index.insert(key, i);
        self.positions.push(p);
        self.uv.push(uv.unwrap_or([0.0; 2]));
        Ok(i)
    }

    /// Add a triangle of welded vertices; dropped when welding collapsed it.
    fn triangle(&mut self, t: [u32; 3]) {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            self.collapsed += 1;
        } else {
            self.triangles.push(t);
        }
    }

    /// Add vertices to a named group (groups of the same name merge).
    fn group(&mut self, name: &str, members: &[u32]) {
        if !members.is_empty() {
            self.groups
                .entry(name.to_string())
                .or_default()
                .extend_from_slice(members);
        }
    }

    fn finish(self) -> Result<TriMesh, MeshError> {
        if self.triangles.is_empty() {
            return Err(format_err(self.path, "has no triangles"));
        }
        if self.collapsed > 0 {
            tracing::debug!(
                path = %self.path.display(),
                collapsed = self.collapsed,
                "dropped triangles whose corners welding merged"
            );
        }
        // Texture v points up in OBJ and PLY (and here in glTF, turned on
        // reading); material v runs down, 0 at the top edge as a grid's row 0.
        let uv = self
            .all_uv
            .then(|| self.uv.iter().map(|t| [t[0], 1.0 - t[1]]).collect());
        TriMesh::validated(
            self.positions,
            uv,
            self.triangles,
            self.groups,
            &self.path.display().to_string(),
        )
    }
}

// ---------------------------------------------------------------------------
// OBJ

/// Read an OBJ file: every object or group (`o`, `g`) a vertex group, all of
/// them one mesh. Materials are not read; polylines (`l`) and points are
/// ignored.
fn read_obj(path: &Path) -> Result<Builder<'_>, MeshError> {
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

// ---------------------------------------------------------------------------
// PLY

/// The `vertex` properties read: position, then the texture-coordinate names
/// in use.
const PLY_VERTEX: [&str; 11] = [
    "x",
    "y",
    "z",
    "u",
    "v",
    "s",
    "t",
    "texture_u",
    "texture_v",
    "texture_s",
    "texture_t",
];

/// Pairs of texture-coordinate names, in order of preference.
const PLY_UV: [(&str, &str); 4] = [
    ("u", "v"),
    ("s", "t"),
    ("texture_u", "texture_v"),
    ("texture_s", "texture_t"),
];

/// The face property listing corners, in order of preference.
const PLY_FACE: [&str; 2] = ["vertex_indices", "vertex_index"];

/// The PLY vertex properties a mesh keeps: [`PLY_VERTEX`].
#[derive(Debug, Clone, Copy, Default)]
struct MeshVertex;

impl crate::ply::Names for MeshVertex {
    const NAMES: &'static [&'static str] = &PLY_VERTEX;
}

/// One PLY vertex as read.
type PlyVertex = crate::ply::Scalars<MeshVertex>;

/// One PLY face as read: its corner list under each name of [`PLY_FACE`].
#[derive(Debug, Default, Clone)]
struct PlyFace {
    corners: [Vec<i64>; 2],
}

impl PlyFace {
    fn put(&mut self, name: &str, values: impl IntoIterator<Item = i64>) -> PropertyAccessResult {
        match PLY_FACE.iter().position(|n| *n == name) {
            Some(k) => {
                self.corners[k] = values.into_iter().collect();
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
}

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        PlyFace::default()
    }
    fn set_list_char(&mut self, name: &str, value: Vec<i8>) -> PropertyAccessResult {
        self.put(name, value.into_iter().map(i64::from))
    }
    fn set_list_uchar(&mut self, name: &str, value: Vec<u8>) -> PropertyAccessResult {
        self.put(name, value.into_iter().map(i64::from))
    }
    fn set_list_short(&mut self, name: &str, value: Vec<i16>) -> PropertyAccessResult {
        self.put(name, value.into_iter().map(i64::from))
    }
    fn set_list_ushort(&mut self, name: &str, value: Vec<u16>) -> PropertyAccessResult {
        self.put(name, value.into_iter().map(i64::from))
    }
    fn set_list_int(&mut self, name: &str, value: Vec<i32>) -> PropertyAccessResult {
        self.put(name, value.into_iter().map(i64::from))
    }
    fn set_list_uint(&mut self, name: &str, value: Vec<u32>) -> PropertyAccessResult {
        self.put(name, value.into_iter().map(i64::from))
    }
}

fn is_integer(t: &ScalarType) -> bool {
    !matches!(t, ScalarType::Float | ScalarType::Double)
}

/// Read a PLY file: `vertex` with scalar `x y z` and optional texture
/// coordinates (`u v`, `s t`, `texture_u texture_v` or `texture_s
/// texture_t`), `face` with an integer list `vertex_indices` (or
/// `vertex_index`); polygons fan-triangulated.
fn read_ply(path: &Path) -> Result<Builder<'_>, MeshError> {
    let file = std::fs::File::open(path).map_err(io_err(path))?;
    let mut reader = Reader::new(BufReader::new(file));
    let header = crate::ply::read_header::<PlyVertex, _>(&mut reader).map_err(|m| format_err(path, m))?;
    let Some(vertex_def) = header.elements.get("vertex") else {
        return Err(format_err(path, "PLY file has no `vertex` element"));
    };
    let props = &vertex_def.properties;
    let scalar = |name: &str| matches!(props.get(name).map(|p| &p.data_type), Some(PropertyType::Scalar(_)));
    crate::ply::check_xyz(props).map_err(|m| format_err(path, m))?;
    for (u, v) in PLY_UV {
        match (props.contains_key(u), props.contains_key(v)) {
            (true, false) => {
                return Err(format_err(
                    path,
                    format!("PLY vertex has texture coordinate `{u}` but no `{v}`"),
                ))
            }
            (false, true) => {
                return Err(format_err(
                    path,
                    format!("PLY vertex has texture coordinate `{v}` but no `{u}`"),
                ))
            }
            (true, true) if !(scalar(u) && scalar(v)) => {
                return Err(format_err(
                    path,
                    format!("PLY vertex texture coordinate `{u}` or `{v}` is a list, expected a scalar"),
                ))
            }
            _ => {}
        }
    }
    let uv_names = PLY_UV.into_iter().find(|(u, v)| scalar(u) && scalar(v));
    let Some(face_def) = header.elements.get("face") else {
        return Err(format_err(
            path,
            "PLY file has no `face` element (a point cloud, not a mesh?)",
        ));
    };
    let Some((face_slot, face_prop)) = PLY_FACE
        .iter()
        .enumerate()
        .find_map(|(k, n)| face_def.properties.get(*n).map(|p| (k, p)))
    else {
        return Err(format_err(
            path,
            "PLY face element has no `vertex_indices` (or `vertex_index`) property",
        ));
    };
    match &face_prop.data_type {
        PropertyType::List(_, t) if is_integer(t) => {}
        PropertyType::List(_, t) => {
            return Err(format_err(
                path,
                format!(
                    "PLY face property `{}` is a list of {t:?}, expected integers",
                    face_prop.name
                ),
            ))
        }
        PropertyType::Scalar(_) => {
            return Err(format_err(
                path,
                format!("PLY face property `{}` is a scalar, expected a list", face_prop.name),
            ))
        }
    }

    let mut vertices: Option<Vec<PlyVertex>> = None;
    let mut faces: Option<Vec<PlyFace>> = None;
    for (name, def) in &header.elements {
        match name.as_str() {
            "vertex" => {
                vertices = Some(
                    Parser::<PlyVertex>::new()
                        .read_payload_for_element(&mut reader, def, &header)
                        .map_err(|e| format_err(path, format!("PLY vertex data: {e}")))?,
                )
            }
            "face" => {
                faces = Some(
                    Parser::<PlyFace>::new()
                        .read_payload_for_element(&mut reader, def, &header)
                        .map_err(|e| format_err(path, format!("PLY face data: {e}")))?,
                )
            }
            // Other elements (edges, materials…) are read and dropped.
            _ => {
                Parser::<DefaultElement>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| format_err(path, format!("PLY element `{name}`: {e}")))?;
            }
        }
        if vertices.is_some() && faces.is_some() {
            break;
        }
    }
    let vertices = vertices.unwrap_or_default();
    let faces = faces.unwrap_or_default();

    let mut mesh = Builder::new(path);
    let mut ids = Vec::with_capacity(vertices.len());
    for v in &vertices {
        let uv = uv_names.map(|(u, w)| [v.get(u).unwrap_or(0.0), v.get(w).unwrap_or(0.0)]);
        ids.push(mesh.vertex([v.v[0], v.v[1], v.v[2]], uv)?);
    }
    for (f, face) in faces.iter().enumerate() {
        let corners = &face.corners[face_slot];
        if corners.len() < 3 {
            return Err(format_err(
                path,
                format!("PLY face {f}: {} corners (a face needs three or more)", corners.len()),
            ));
        }
        let mut welded = Vec::with_capacity(corners.len());
        for &i in corners {
            let id = usize::try_from(i).ok().and_then(|i| ids.get(i)).ok_or_else(|| {
                format_err(
                    path,
                    format!("PLY face {f}: vertex index {i} out of range ({} vertices)", ids.len()),
                )
            })?;
            welded.push(*id);
        }
        // Fan triangulation around the first corner.
        for k in 1..welded.len() - 1 {
            mesh.triangle([welded[0], welded[k], welded[k + 1]]);
        }
    }
    Ok(mesh)
}

// ---------------------------------------------------------------------------
// glTF

type Mat4 = [[f64; 4]; 4];

const IDENTITY: Mat4 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// `a · b` of column-major matrices (`m[column][row]`).
fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for c in 0..4 {
        for r in 0..4 {
            m[c][r] = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

/// The point `p` moved by the affine column-major matrix `m`.
fn transform_point(m: &Mat4, p: [f32; 3]) -> [f64; 3] {
    let p = p.map(f64::from);
    let mut q = [0.0; 3];
    for r in 0..3 {
        q[r] = m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r];
    }
    q
}

/// Determinant of the linear part: negative for a mirroring transform, which
/// turns triangles inside out (glTF: their winding is reversed).
fn det3(m: &Mat4) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[2][1] * m[1][2]) - m[1][0] * (m[0][1] * m[2][2] - m[2][1] * m[0][2])
        + m[2][0] * (m[0][1] * m[1][2] - m[1][1] * m[0][2])
}

/// Read a `.gltf` or `.glb` file: every triangle primitive of every node of
/// the default scene (or the first, or every root node when there is none),
/// placed by the node's world transform; each node a vertex group.
fn read_gltf(path: &Path) -> Result<Builder<'_>, MeshError> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    let gltf = gltf::Gltf::from_slice(&bytes).map_err(|e| format_err(path, format!("glTF: {e}")))?;
    drop(bytes);
    let gltf::Gltf { document, blob } = gltf;
    let buffers = gltf_buffers(path, &document, blob)?;
    let node_count = document.nodes().len();
    let roots: Vec<gltf::Node> = match document.default_scene().or_else(|| document.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut is_child = vec![false; node_count];
            for node in document.nodes() {
                for child in node.children() {
                    if let Some(c) = is_child.get_mut(child.index()) {
                        *c = true;
                    }
                }
            }
            document
                .nodes()
                .filter(|n| !is_child.get(n.index()).copied().unwrap_or(false))
                .collect()
        }
    };
    let mut mesh = Builder::new(path);
    let mut seen = vec![false; node_count];
    // Depth first without recursion: a hierarchy can be deep.
    let mut stack: Vec<(gltf::Node, Mat4)> = roots.into_iter().rev().map(|n| (n, IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        match seen.get_mut(node.index()) {
            Some(s) if !*s => *s = true,
            _ => {
                return Err(format_err(
                    path,
                    format!(
                        "glTF node {} is reached twice from the scene (a node has one parent at most)",
                        node.index()
                    ),
                ))
            }
        }
        let local = node.transform().matrix().map(|col| col.map(f64::from));
        let world = mat_mul(&parent, &local);
        if let Some(m) = node.mesh() {
            gltf_mesh(&mut mesh, &node, &m, &world, &buffers)?;
        }
        let children: Vec<gltf::Node> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world)));
    }
    Ok(mesh)
}

/// Add the triangle primitives of `m`, instanced at `node` with transform
/// `world`.
fn gltf_mesh(
    mesh: &mut Builder<'_>,
    node: &gltf::Node,
    m: &gltf::Mesh,
    world: &Mat4,
    buffers: &[Vec<u8>],
) -> Result<(), MeshError> {
    let path = mesh.path;
    let name = node
        .name()
        .or_else(|| m.name())
        .map_or_else(|| format!("node{}", node.index()), str::to_string);
    let mirrored = det3(world) < 0.0;
    let mut members = Vec::new();
    for primitive in m.primitives() {
        let at = format!(
            "glTF mesh {} (node {}), primitive {}",
            m.index(),
            node.index(),
            primitive.index()
        );
        let fail = |message: String| format_err(path, format!("{at}: {message}"));
        match primitive.mode() {
            Mode::Triangles => {}
            Mode::TriangleStrip => return Err(fail("mode TRIANGLE_STRIP is not supported (only TRIANGLES)".into())),
            Mode::TriangleFan => return Err(fail("mode TRIANGLE_FAN is not supported (only TRIANGLES)".into())),
            // Points and lines make no cloth.
            _ => continue,
        }
        let Some(positions) = primitive.get(&Semantic::Positions) else {
            return Err(fail("no POSITION attribute".into()));
        };
        check_accessor(&positions, "POSITION", Dimensions::Vec3, &[DataType::F32], buffers).map_err(fail)?;
        let tex_coords = primitive.get(&Semantic::TexCoords(0));
        if let Some(a) = &tex_coords {
            check_accessor(
                a,
                "TEXCOORD_0",
                Dimensions::Vec2,
                &[DataType::F32, DataType::U8, DataType::U16],
                buffers,
            )
            .map_err(fail)?;
            if a.count() != positions.count() {
                return Err(fail(format!(
                    "TEXCOORD_0 (accessor {}) has {} elements, POSITION (accessor {}) {}",
                    a.index(),
                    a.count(),
                    positions.index(),
                    positions.count()
                )));
            }
        }
        let indices = primitive.indices();
        if let Some(a) = &indices {
            check_accessor(
                a,
                "indices",
                Dimensions::Scalar,
                &[DataType::U8, DataType::U16, DataType::U32],
                buffers,
            )
            .map_err(fail)?;
        }

        let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let unreadable = |what: &str, index: usize| fail(format!("{what} (accessor {index}) cannot be read"));
        let points: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or_else(|| unreadable("POSITION", positions.index()))?
            .collect();
        let uv: Option<Vec<[f32; 2]>> = match &tex_coords {
            Some(a) => Some(
                reader
                    .read_tex_coords(0)
                    .ok_or_else(|| unreadable("TEXCOORD_0", a.index()))?
                    .into_f32()
                    .collect(),
            ),
            None => None,
        };
        let mut ids = Vec::with_capacity(points.len());
        for (k, p) in points.iter().enumerate() {
            // glTF's v runs down the texture; OBJ's and PLY's run up.
            let t = uv
                .as_ref()
                .and_then(|uv| uv.get(k))
                .map(|t| [f64::from(t[0]), 1.0 - f64::from(t[1])]);
            ids.push(mesh.vertex(transform_point(world, *p), t)?);
        }
        let corners: Vec<u32> = match &indices {
            Some(a) => reader
                .read_indices()
                .ok_or_else(|| unreadable("indices", a.index()))?
                .into_u32()
                .collect(),
            None => (0..u32::try_from(ids.len()).unwrap_or(u32::MAX)).collect(),
        };
        if !corners.len().is_multiple_of(3) {
            return Err(fail(format!(
                "{} {}, not a multiple of 3",
                corners.len(),
                if indices.is_some() {
                    "indices"
                } else {
                    "vertices without indices"
                }
            )));
        }
        for (t, tri) in corners.chunks_exact(3).enumerate() {
            let mut welded = [0u32; 3];
            for (c, &i) in tri.iter().enumerate() {
                welded[c] = *ids.get(i as usize).ok_or_else(|| {
                    fail(format!(
                        "triangle {t}: vertex index {i} out of range ({} vertices)",
                        ids.len()
                    ))
                })?;
            }
            if mirrored {
                welded.swap(1, 2);
            }
            mesh.triangle(welded);
        }
        members.extend_from_slice(&ids);
    }
    mesh.group(&name, &members);
    Ok(())
}

fn type_name(t: Dimensions) -> &'static str {
    match t {
        Dimensions::Scalar => "SCALAR",
        Dimensions::Vec2 => "VEC2",
        Dimensions::Vec3 => "VEC3",
        Dimensions::Vec4 => "VEC4",
        Dimensions::Mat2 => "MAT2",
        Dimensions::Mat3 => "MAT3",
        Dimensions::Mat4 => "MAT4",
    }
}

fn component_name(t: DataType) -> &'static str {
    match t {
        DataType::I8 => "BYTE",
        DataType::U8 => "UNSIGNED_BYTE",
        DataType::I16 => "SHORT",
        DataType::U16 => "UNSIGNED_SHORT",
        DataType::U32 => "UNSIGNED_INT",
        DataType::F32 => "FLOAT",
    }
}

/// Check that the gltf crate's reader can read `accessor` as `what` without
/// panicking: its type, a buffer view, and every byte inside the view and
/// the view inside its (loaded) buffer.
fn check_accessor(
    accessor: &gltf::Accessor,
    what: &str,
    dimensions: Dimensions,
    data_types: &[DataType],
    buffers: &[Vec<u8>],
) -> Result<(), String> {
    let at = format!("{what} (accessor {})", accessor.index());
    if accessor.sparse().is_some() {
        return Err(format!("{at} is sparse (not supported)"));
    }
    if accessor.dimensions() != dimensions {
        return Err(format!(
            "{at} is {}, expected {}",
            type_name(accessor.dimensions()),
            type_name(dimensions)
        ));
    }
    if !data_types.contains(&accessor.data_type()) {
        let expected: Vec<&str> = data_types.iter().map(|t| component_name(*t)).collect();
        return Err(format!(
            "{at} has {} components, expected {}",
            component_name(accessor.data_type()),
            expected.join(" or ")
        ));
    }
    let count = accessor.count();
    if count == 0 {
        return Err(format!("{at} is empty (count 0)"));
    }
    let Some(view) = accessor.view() else {
        return Err(format!("{at} has no bufferView"));
    };
    let size = accessor.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!(
            "{at}: bufferView {} has byteStride {stride}, less than the {size} bytes of an element",
            view.index()
        ));
    }
    let buffer = view.buffer().index();
    let available = buffers.get(buffer).map_or(0, Vec::len);
    if view
        .offset()
        .checked_add(view.length())
        .is_none_or(|end| end > available)
    {
        return Err(format!(
            "{at}: bufferView {} (bytes {}..{}+{}) runs past the end of buffer {buffer} ({available} bytes)",
            view.index(),
            view.offset(),
            view.offset(),
            view.length()
        ));
    }
    let end = stride
        .checked_mul(count - 1)
        .and_then(|x| x.checked_add(size))
        .and_then(|x| x.checked_add(accessor.offset()));
    if end.is_none_or(|end| end > view.length()) {
        return Err(format!(
            "{at}: {count} elements of {size} bytes every {stride} from byte {} run past the end of bufferView {} ({} bytes)",
            accessor.offset(),
            view.index(),
            view.length()
        ));
    }
    Ok(())
}

/// Every buffer's bytes: the GLB binary chunk, a `data:` URI's base64, or a
/// file beside the glTF file.
fn gltf_buffers(path: &Path, document: &gltf::Document, mut blob: Option<Vec<u8>>) -> Result<Vec<Vec<u8>>, MeshError> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut buffers = Vec::new();
    for buffer in document.buffers() {
        let i = buffer.index();
        let (data, source) = match buffer.source() {
            gltf::buffer::Source::Bin => {
                let data = blob.take().ok_or_else(|| {
                    format_err(
                        path,
                        format!("glTF buffer {i} refers to the GLB binary chunk, but there is none (or another buffer has it)"),
                    )
                })?;
                (data, "the GLB binary chunk".to_string())
            }
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let data = data_uri(uri).map_err(|m| format_err(path, format!("glTF buffer {i}: {m}")))?;
                (data, "its data: URI".to_string())
            }
            gltf::buffer::Source::Uri(uri) => {
                if has_scheme(uri) {
                    return Err(format_err(
                        path,
                        format!("glTF buffer {i}: URI `{uri}` is not a relative file path or a data: URI"),
                    ));
                }
                let file = dir.join(uri);
                let data = std::fs::read(&file).map_err(|e| MeshError::Io {
                    path: path.to_path_buf(),
                    source: std::io::Error::new(e.kind(), format!("glTF buffer {i} `{uri}` ({}): {e}", file.display())),
                })?;
                (data, format!("`{uri}`"))
            }
        };
        if data.len() < buffer.length() {
            return Err(format_err(
                path,
                format!(
                    "glTF buffer {i} ({source}) has {} bytes, but its byteLength is {}",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// Whether `uri` starts with a scheme (`http:`, `file:` …): RFC 3986's
/// letter, then letters, digits, `+`, `-`, `.`, then a colon. One letter is
/// taken for a Windows drive, not a scheme.
fn has_scheme(uri: &str) -> bool {
    uri.split_once(':').is_some_and(|(scheme, _)| {
        scheme.len() > 1
            && scheme.starts_with(|c: char| c.is_ascii_alphabetic())
            && scheme
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
    })
}

/// The bytes of a base64 `data:` URI (`data:application/octet-stream;base64,…`).
fn data_uri(uri: &str) -> Result<Vec<u8>, String> {
    use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};
    use base64::Engine as _;
    let rest = &uri["data:".len()..];
    let Some((meta, payload)) = rest.split_once(',') else {
        return Err("data: URI without a comma before its data".into());
    };
    if !meta.ends_with(";base64") {
        return Err(format!(
            "data: URI `data:{meta},…` is not base64 (only `;base64` data is read)"
        ));
    }
    // Padding optional: some writers leave it out.
    let engine = GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        GeneralPurposeConfig::new().with_decode_padding_mode(DecodePaddingMode::Indifferent),
    );
    engine
        .decode(payload.trim())
        .map_err(|e| format!("data: URI: invalid base64: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::vec3::{cross, norm, sub};
    use base64::Engine as _;

    /// Σ |(b − a) × (c − a)| / 2 over the triangles (m²).
    fn total_area(m: &TriMesh) -> f64 {
        m.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                0.5 * norm(cross(sub(b, a), sub(c, a)))
            })
            .sum()
    }

    fn write(dir: &tempfile::TempDir, name: &str, contents: &[u8]) -> std::path::PathBuf {
        let path = dir.path().join(name);
        std::fs::write(&path, contents).expect("write test file");
        path
    }

    fn sorted_positions(m: &TriMesh) -> Vec<[f64; 3]> {
        let mut p = m.positions.clone();
        p.sort_by(|a, b| {
            a.iter()
                .zip(b)
                .map(|(x, y)| x.total_cmp(y))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        p
    }

    fn format_message(e: MeshError) -> String {
        match e {
            MeshError::Format { message, .. } => message,
            other => panic!("expected a Format error, got {other:?}"),
        }
    }

    #[test]
    fn obj_square_split_at_a_uv_seam_welds_to_four_vertices_with_a_group_per_object() {
        let dir = tempfile::tempdir().unwrap();
        // Vertices 1 and 3 appear with two texture coordinates each: tobj
        // splits them, welding joins them again.
        let obj = "\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0.5 0
vt 0.5 1
vt 0 1
o left
f 1/1 2/2 3/3
g right
f 1/4 3/5 4/6
";
        let path = write(&dir, "square.OBJ", obj.as_bytes());
        let m = load(&path).unwrap();
        assert_eq!(m.vertices(), 4);
        assert_eq!(m.triangles.len(), 2);
        assert!(m.uv_from_file);
        assert!((total_area(&m) - 1.0).abs() < 1e-12);
        assert_eq!(m.groups.keys().collect::<Vec<_>>(), ["left", "right"]);
        assert_eq!(m.groups["left"].len(), 3);
        assert_eq!(m.groups["right"].len(), 3);
        // The welded corner of both objects is one vertex, in both groups.
        let shared: Vec<_> = m.groups["left"]
            .iter()
            .filter(|i| m.groups["right"].contains(i))
            .collect();
        assert_eq!(shared.len(), 2);
    }

    #[test]
    fn obj_quad_face_is_triangulated_into_two_triangles() {
        let dir = tempfile::tempdir().unwrap();
        let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
        let m = load(&write(&dir, "quad.obj", obj.as_bytes())).unwrap();
        assert_eq!(m.vertices(), 4);
        assert_eq!(m.triangles.len(), 2);
        assert!(!m.uv_from_file);
        assert!((total_area(&m) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn obj_triangle_collapsed_by_welding_is_dropped_and_polylines_ignored() {
        let dir = tempfile::tempdir().unwrap();
        // Vertex 5 repeats vertex 3's position: triangle 3 5 4 collapses.
        let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 1 1 -0\nf 1 2 3\nf 1 3 4\nf 3 5 4\nl 1 2 3 4\n";
        let m = load(&write(&dir, "weld.obj", obj.as_bytes())).unwrap();
        assert_eq!(m.vertices(), 4);
        assert_eq!(m.triangles.len(), 2);
    }

    #[test]
    fn ply_quad_with_uv_matches_the_obj_quad() {
        let dir = tempfile::tempdir().unwrap();
        let ply = "\
ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
property float u
property float v
element face 1
property list uchar int vertex_indices
end_header
0 0 0 0 0
1 0 0 1 0
1 1 0 1 1
0 1 0 0 1
4 0 1 2 3
";
        let from_ply = load(&write(&dir, "quad.ply", ply.as_bytes())).unwrap();
        let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
        let from_obj = load(&write(&dir, "quad.obj", obj.as_bytes())).unwrap();
        assert_eq!(from_ply.triangles.len(), 2);
        assert!(from_ply.uv_from_file);
        assert!(from_ply.groups.is_empty());
        assert_eq!(sorted_positions(&from_ply), sorted_positions(&from_obj));
        assert!((total_area(&from_ply) - total_area(&from_obj)).abs() < 1e-12);
        assert!((total_area(&from_ply) - 1.0).abs() < 1e-12);
    }

    /// A unit square in the xy plane: positions (f32), UVs (f32) and u16
    /// indices in one buffer, and the glTF JSON describing it with a node
    /// translated by (1, 2, 3). `uri` is the buffer's URI (None in a GLB).
    fn square_gltf(uri: Option<&str>) -> (String, Vec<u8>) {
        let mut bin = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            for x in p {
                bin.extend_from_slice(&x.to_le_bytes());
            }
        }
        for t in [[0f32, 1.], [1., 1.], [1., 0.], [0., 0.]] {
            for x in t {
                bin.extend_from_slice(&x.to_le_bytes());
            }
        }
        for i in [0u16, 1, 2, 0, 2, 3] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        assert_eq!(bin.len(), 92);
        let uri = uri.map_or(String::new(), |u| format!(r#""uri": "{u}","#));
        let json = format!(
            r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"name": "cloth", "mesh": 0, "translation": [1, 2, 3]}}],
  "meshes": [{{"name": "sheet", "primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "indices": 2}}]}}],
  "buffers": [{{{uri} "byteLength": 92}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 80, "byteLength": 12}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"}},
    {{"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ]
}}"#
        );
        (json, bin)
    }

    fn check_translated_square(m: &TriMesh) {
        assert_eq!(m.vertices(), 4);
        assert_eq!(m.triangles.len(), 2);
        assert!(m.uv_from_file);
        assert_eq!(
            sorted_positions(m),
            vec![[1.0, 2.0, 3.0], [1.0, 3.0, 3.0], [2.0, 2.0, 3.0], [2.0, 3.0, 3.0]]
        );
        assert!((total_area(m) - 1.0).abs() < 1e-12);
        assert_eq!(m.groups.keys().collect::<Vec<_>>(), ["cloth"]);
        assert_eq!(m.groups["cloth"], vec![0, 1, 2, 3]);
        // Material v runs down, as glTF's own v: the vertex at y = 3 (the
        // top) has v = 0.
        for (p, t) in m.positions.iter().zip(&m.uv) {
            assert_eq!(t[1], 3.0 - p[1]);
        }
    }

    #[test]
    fn gltf_with_embedded_buffer_applies_the_node_translation() {
        let dir = tempfile::tempdir().unwrap();
        let (_, bin) = square_gltf(None);
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&bin)
        );
        let (json, _) = square_gltf(Some(&uri));
        let m = load(&write(&dir, "square.gltf", json.as_bytes())).unwrap();
        check_translated_square(&m);
    }

    #[test]
    fn gltf_with_external_buffer_reads_the_file_beside_it() {
        let dir = tempfile::tempdir().unwrap();
        let (json, bin) = square_gltf(Some("square.bin"));
        write(&dir, "square.bin", &bin);
        let m = load(&write(&dir, "square.gltf", json.as_bytes())).unwrap();
        check_translated_square(&m);
    }

    #[test]
    fn glb_container_applies_the_node_translation() {
        let dir = tempfile::tempdir().unwrap();
        let (json, mut bin) = square_gltf(None);
        let mut json = json.into_bytes();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut glb = Vec::new();
        glb.extend_from_slice(b"glTF");
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&(total as u32).to_le_bytes());
        glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
        glb.extend_from_slice(b"JSON");
        glb.extend_from_slice(&json);
        glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        glb.extend_from_slice(b"BIN\0");
        glb.extend_from_slice(&bin);
        let m = load(&write(&dir, "square.glb", &glb)).unwrap();
        check_translated_square(&m);
    }

    #[test]
    fn bad_inputs_give_errors_that_name_the_place() {
        let dir = tempfile::tempdir().unwrap();

        let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                   element face 2\nproperty list uchar int vertex_indices\nend_header\n\
                   0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 7\n";
        let e = format_message(load(&write(&dir, "bad.ply", ply.as_bytes())).unwrap_err());
        assert!(
            e.contains("face 1") && e.contains("7") && e.contains("out of range"),
            "{e}"
        );

        let ply2 = ply.replace("3 0 1 7", "2 0 1");
        let e = format_message(load(&write(&dir, "short.ply", ply2.as_bytes())).unwrap_err());
        assert!(e.contains("face 1") && e.contains("2 corners"), "{e}");

        let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n";
        let e = format_message(load(&write(&dir, "bad.obj", obj.as_bytes())).unwrap_err());
        assert!(e.contains("line 5") && e.contains("vertex 9 out of range"), "{e}");

        let e = format_message(load(&write(&dir, "cloth.stl", b"solid")).unwrap_err());
        assert!(e.contains("`.stl`") && e.contains(".obj") && e.contains(".glb"), "{e}");

        match load(&dir.path().join("missing.obj")).unwrap_err() {
            MeshError::Io { path, source } => {
                assert!(path.ends_with("missing.obj"));
                assert_eq!(source.kind(), std::io::ErrorKind::NotFound);
            }
            other => panic!("expected an Io error, got {other:?}"),
        }

        let (json, _) = square_gltf(Some("gone.bin"));
        let e = load(&write(&dir, "external.gltf", json.as_bytes())).unwrap_err();
        assert!(matches!(e, MeshError::Io { .. }), "{e:?}");
        let text = e.to_string();
        assert!(text.contains("gone.bin") && text.contains("buffer 0"), "{text}");

        let (json, bin) = square_gltf(Some("square.bin"));
        write(&dir, "square.bin", &bin);
        let strip = json.replace(r#""indices": 2}"#, r#""indices": 2, "mode": 5}"#);
        let e = format_message(load(&write(&dir, "strip.gltf", strip.as_bytes())).unwrap_err());
        assert!(e.contains("TRIANGLE_STRIP") && e.contains("primitive 0"), "{e}");

        let overrun = json.replace(r#""count": 6"#, r#""count": 9"#);
        let e = format_message(load(&write(&dir, "overrun.gltf", overrun.as_bytes())).unwrap_err());
        assert!(e.contains("accessor 2") && e.contains("bufferView 2"), "{e}");

        let empty = "v 0 0 0\nv 1 0 0\n";
        let e = format_message(load(&write(&dir, "empty.obj", empty.as_bytes())).unwrap_err());
        assert!(e.contains("has no triangles"), "{e}");
    }

    #[test]
    fn malformed_files_are_errors_that_name_the_place_not_panics() {
        let dir = tempfile::tempdir().unwrap();
        let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        let objs: [(Vec<u8>, &str); 10] = [
            (
                format!("{tri}vt 0 0\nf 1/-5 2/1 3/1\n").into(),
                "line 5 (face 0): relative texture coordinate index -5",
            ),
            (
                "f -1 -2 -3\nv 0 0 0\n".into(),
                "line 1 (face 0): relative vertex index -1",
            ),
            (
                format!("{tri}f 1/1/1/1 2 3\n").into(),
                "line 4 (face 0): `1/1/1/1` is not a face corner",
            ),
            (format!("{tri}f 0 1 2\n").into(), "line 4 (face 0): vertex index 0"),
            (format!("{tri}f 1 2\n").into(), "line 4 (face 0): 2 corners"),
            (
                "v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".into(),
                "line 1: a `v` line needs three numbers",
            ),
            ("v 0 0 0 0\n".into(), "line 1: a `v` line with weight w = 0"),
            (
                [format!("{tri}f 1 2 3\n").as_bytes(), b"\xff\n"].concat(),
                "line 5, column 1: not valid UTF-8",
            ),
            ("v 0 0 0 1 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".into(), "vertex colours"),
            (Vec::new(), "has no triangles"),
        ];
        for (k, (obj, expected)) in objs.iter().enumerate() {
            let e = format_message(load(&write(&dir, &format!("m{k}.obj"), obj)).unwrap_err());
            assert!(e.contains(expected), "OBJ {k}: `{e}` should contain `{expected}`");
        }

        let (json, bin) = square_gltf(Some("square.bin"));
        write(&dir, "square.bin", &bin);
        let gltfs = [
            (
                json.replace(r#""byteLength": 48}"#, r#""byteLength": 48, "byteStride": 4}"#),
                "primitive 0: POSITION (accessor 0): bufferView 0 has byteStride 4",
            ),
            (
                json.replace(r#""count": 6"#, r#""count": 0"#),
                "indices (accessor 2) is empty",
            ),
            (
                json.replace(r#""componentType": 5123"#, r#""componentType": 5126"#),
                "indices (accessor 2) has FLOAT components",
            ),
            (
                json.replace(r#""type": "VEC2""#, r#""type": "VEC3""#),
                "TEXCOORD_0 (accessor 1) is VEC3",
            ),
            (
                json.replace(r#""byteLength": 92"#, r#""byteLength": 200"#),
                "buffer 0 (`square.bin`) has 92 bytes",
            ),
            (
                json.replace(r#""byteLength": 12}"#, r#""byteLength": 18446744073709551615}"#),
                "bufferView 2 (bytes 80..80+18446744073709551615) runs past the end of buffer 0",
            ),
            (
                json.replace(r#""mesh": 0,"#, r#""mesh": 0, "children": [0],"#),
                "node 0 is reached twice",
            ),
            (
                json.replace("square.bin", "data:application/octet-stream;base64,@@@"),
                "buffer 0: data: URI: invalid base64",
            ),
            (
                json.replace("square.bin", "http://example.com/a.bin"),
                "buffer 0: URI `http://example.com/a.bin`",
            ),
        ];
        for (k, (gltf, expected)) in gltfs.iter().enumerate() {
            let e = format_message(load(&write(&dir, &format!("g{k}.gltf"), gltf.as_bytes())).unwrap_err());
            assert!(e.contains(expected), "glTF {k}: `{e}` should contain `{expected}`");
        }
        // No scene: the root nodes are read.
        let no_scene = json
            .replace(r#""scene": 0,"#, "")
            .replace(r#""scenes": [{"nodes": [0]}],"#, "");
        check_translated_square(&load(&write(&dir, "no_scene.gltf", no_scene.as_bytes())).unwrap());

        for (k, glb) in [&b"glTF\x02\0\0\0\xff\0\0\0"[..], b"glTF", b""].iter().enumerate() {
            let e = format_message(load(&write(&dir, &format!("b{k}.glb"), glb)).unwrap_err());
            assert!(e.starts_with("glTF: "), "GLB {k}: {e}");
        }

        let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
        let points = "0 0 0\n1 0 0\n0 1 0\n";
        let faces = "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
        let plys = [
            (
                format!("{header}{faces}{points}3 0 1 -1\n"),
                "PLY face 0: vertex index -1 out of range",
            ),
            (
                format!("{header}property float u\n{faces}0 0 0 0\n1 0 0 0\n0 1 0 0\n3 0 1 2\n"),
                "texture coordinate `u` but no `v`",
            ),
            (format!("{header}end_header\n{points}"), "no `face` element"),
            (
                format!("{header}{}{points}3 0 1 2\n", faces.replace("int", "float")),
                "`vertex_indices` is a list of Float",
            ),
            (format!("{header}{faces}{points}3 0 1\n"), "PLY face data: Line 13"),
        ];
        for (k, (ply, expected)) in plys.iter().enumerate() {
            let e = format_message(load(&write(&dir, &format!("p{k}.ply"), ply.as_bytes())).unwrap_err());
            assert!(e.contains(expected), "PLY {k}: `{e}` should contain `{expected}`");
        }
    }
}
