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

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use super::{MeshError, TriMesh};

mod gltf_file;
mod obj;
mod ply;
#[cfg(test)]
mod tests;

use gltf_file::read_gltf;
use obj::read_obj;
use ply::read_ply;

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
