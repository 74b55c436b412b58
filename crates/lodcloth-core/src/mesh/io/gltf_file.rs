//! glTF 2.0: `.gltf` with embedded or external buffers, `.glb` (read with
//! `gltf`, buffers resolved here).

use std::path::Path;

use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};

use super::{format_err, io_err, Builder, MeshError};

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
pub(super) fn read_gltf(path: &Path) -> Result<Builder<'_>, MeshError> {
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
