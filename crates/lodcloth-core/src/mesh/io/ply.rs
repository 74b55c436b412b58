//! PLY, ASCII or binary (read with `ply-rs-bw`).

use std::io::BufReader;
use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType};

use super::{format_err, io_err, Builder, MeshError};

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
pub(super) fn read_ply(path: &Path) -> Result<Builder<'_>, MeshError> {
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
