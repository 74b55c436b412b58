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
