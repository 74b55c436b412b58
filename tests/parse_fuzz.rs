//! Every file parser fed mutated valid files and random bytes: the service
//! config (`ServiceConfig::from_toml`), scenes (`Scene::load`) and point
//! clouds (`points::io::read`, XYZ and PLY ascii/binary). None panics; every
//! refusal names the file and where in it the problem is (a field path or a
//! line for TOML, a line for XYZ, an element, property or line for PLY); and
//! whatever is accepted is physically valid. Then the physics refusals the
//! product promises, one test each.
//!
//! The mutations start from the shipped files (`config/*.toml`,
//! `config/scenes/*.toml`) and small clouds written here: bit flips, byte
//! writes, truncation, deleted and duplicated lines, a value replaced by a
//! string, a huge, negative or tiny number, NaN, inf, an empty array or a
//! wrong type, inserted unicode, very long or deeply nested lines; plus fully
//! random bytes.

use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use lodcloth::plan::{InstanceKind, Level, PrepareError, Preparer};
use lodcloth::points::{io, PointCloud};
use lodcloth::scene::{Scene, SceneError};
use lodcloth::service::config::{ConfigError, ServiceConfig};
use lodcloth::sim::{SimError, StabilityCheck};
use ply_rs_bw::ply::Encoding;
use proptest::prelude::*;
use proptest::sample::Index;

// ---------------------------------------------------------------- inputs

fn manifest_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every `*.toml` in `dir` (relative to the crate), sorted, as text.
fn toml_files(dir: &str) -> Vec<(PathBuf, String)> {
    let dir = manifest_dir().join(dir);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no TOML files in {}", dir.display());
    files
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p, text)
        })
        .collect()
}

/// The shipped scenes.
fn scenes() -> &'static [(PathBuf, String)] {
    static SCENES: OnceLock<Vec<(PathBuf, String)>> = OnceLock::new();
    SCENES.get_or_init(|| toml_files("config/scenes"))
}

/// The shipped service configs, plus a one-instance config (cheaper to
/// validate, so it gets most of the cases).
fn configs() -> &'static [(PathBuf, String)] {
    static CONFIGS: OnceLock<Vec<(PathBuf, String)>> = OnceLock::new();
    CONFIGS.get_or_init(|| {
        let mut files = toml_files("config");
        files.push((PathBuf::from("small.toml"), SMALL_CONFIG.to_string()));
        files
    })
}

/// One cloth instance with every optional field set.
const SMALL_CONFIG: &str = r#"
prefix = "lodcloth/test"
cache = "out/cache"

[zenoh]
mode = "peer"
listen = ["tcp/127.0.0.1:0"]
connect = []
multicast_scouting = false

[engine]
threads = 2
max_catch_up = 0.1
max_lag = 0.25
metrics_hz = 10.0
publish_hz = 60.0

[estimation]
reference_steps = 600
metric_stride = 40
estimate_stride = 40
fit_frames = 10
fit_iterations = 2
precompute = false

[[instances]]
name = "hanging"
kind = "cloth"
scene = "config/scenes/hanging.toml"
reference = "32x32"
levels = ["8x8", "16x16"]
start = "8x8"
method = "gkd"
integrator = "rk4"
dt = 1e-4
publish_hz = 30.0
shadow_reference = false
loop = true
switch_settle = 0.0167
"#;

/// Small valid clouds in every format `io::read` takes: (file name, bytes).
fn clouds() -> &'static [(&'static str, Vec<u8>)] {
    static CLOUDS: OnceLock<Vec<(&'static str, Vec<u8>)>> = OnceLock::new();
    CLOUDS.get_or_init(|| {
        let positions: Vec<[f64; 3]> = (0..6)
            .map(|i| {
                let t = i as f64;
                [0.1 * t, (0.7 * t).sin(), -0.25 + 0.05 * t * t]
            })
            .collect();
        let normals = positions
            .iter()
            .map(|p| {
                let l = (p[0] * p[0] + p[1] * p[1] + 1.0).sqrt();
                [p[0] / l, p[1] / l, 1.0 / l]
            })
            .collect();
        let bare = PointCloud::new(positions.clone());
        let with_normals = PointCloud {
            positions,
            normals: Some(normals),
        };
        let dir = tempfile::tempdir().expect("temporary directory");
        let written = |name: &str, write: &dyn Fn(&Path) -> Result<(), io::PointsIoError>| {
            let path = dir.path().join(name);
            write(&path).unwrap_or_else(|e| panic!("writing {name}: {e}"));
            std::fs::read(&path).expect("read back")
        };
        let mut out = vec![
            ("bare.xyz", written("bare.xyz", &|p| io::write_xyz(p, &bare))),
            (
                "normals.xyz",
                written("normals.xyz", &|p| io::write_xyz(p, &with_normals)),
            ),
            (
                "ascii.ply",
                written("ascii.ply", &|p| io::write_ply(p, &with_normals, Encoding::Ascii)),
            ),
            (
                "little.ply",
                written("little.ply", &|p| {
                    io::write_ply(p, &with_normals, Encoding::BinaryLittleEndian)
                }),
            ),
            (
                "big.ply",
                written("big.ply", &|p| io::write_ply(p, &bare, Encoding::BinaryBigEndian)),
            ),
        ];
        // Hand-written: comments, commas, CRLF; doubles, an ignored
        // property and a face element after the vertices.
        out.push((
            "hand.xyz",
            b"# x y z\r\n0, 0, 0\r\n1 0 0 # corner\r\n\r\n0 1 0.5\r\n".to_vec(),
        ));
        out.push((
            "hand.ply",
            b"ply\nformat ascii 1.0\ncomment by hand\nelement vertex 3\nproperty double x\nproperty double y\n\
              property double z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\n\
              end_header\n0 0 0 255\n1 0 0 0\n0 1 0.5 10\n3 0 1 2\n"
                .to_vec(),
        ));
        for (name, bytes) in &out {
            let path = dir.path().join(name);
            std::fs::write(&path, bytes).expect("write");
            io::read(&path).unwrap_or_else(|e| panic!("base cloud {name} does not read: {e}"));
        }
        out
    })
}

// ------------------------------------------------------------- mutations

/// One edit of a file's bytes. Positions are taken modulo the current length.
#[derive(Debug, Clone)]
enum Mutation {
    FlipBit(Index, u8),
    SetByte(Index, u8),
    Truncate(Index),
    DeleteLine(Index),
    DuplicateLine(Index),
    /// A TOML table (from a `[` line to the next) written twice.
    DuplicateTable(Index),
    /// The value of the n-th `key = value` (TOML) or the n-th
    /// whitespace-separated token (clouds) replaced.
    ReplaceValue(Index, String),
    /// The n-th number (in TOML: outside comments and strings, also inside
    /// arrays and inline tables) replaced by another number.
    ReplaceNumber(Index, String),
    /// Text inserted at a byte position.
    Insert(Index, String),
    /// A line of `unit` repeated `count` times inserted at the start of a line.
    LongLine(Index, &'static str, usize),
}

/// What a replaced number becomes: the edges of every range the parsers
/// check, and random numbers.
fn number() -> impl Strategy<Value = String> {
    let fixed = prop::sample::select(vec![
        "nan",
        "-nan",
        "inf",
        "-inf",
        "1e308",
        "-1e308",
        "1e-320",
        "5e-324",
        "-5e-324",
        "0",
        "0.0",
        "-0.0",
        "-1",
        "-1e-4",
        "1e-2",
        "0.5",
        "1",
        "2",
        "3",
        "10",
        "1e6",
        "512",
        "513",
        "4096",
        "4097",
        "65536",
        "9223372036854775807",
        "-9223372036854775808",
        "6148914691236517206",
    ]);
    prop_oneof![
        3 => fixed.prop_map(str::to_string),
        1 => any::<f64>().prop_map(toml_float),
        1 => (-1e3..1e3f64).prop_map(toml_float),
        1 => any::<i64>().prop_map(|i| i.to_string()),
        1 => (0..5000i64).prop_map(|i| i.to_string()),
    ]
}

/// `x` as a TOML float.
fn toml_float(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.into()
    } else {
        format!("{x:?}")
    }
}

/// What a replaced value becomes: any of `number()`'s kinds, strings valid
/// elsewhere in the files, wrong types, random text, deep nesting.
fn value() -> impl Strategy<Value = String> {
    let fixed = prop::sample::select(vec![
        "nan",
        "-nan",
        "+nan",
        "inf",
        "-inf",
        "1e308",
        "1.7976931348623157e308",
        "-1e308",
        "1e400",
        "1e-320",
        "5e-324",
        "9223372036854775807",
        "-9223372036854775808",
        "18446744073709551616",
        "6148914691236517206",
        "4294967296",
        "0",
        "0.0",
        "-0.0",
        "-1",
        "-1.0",
        "-1e-4",
        "1",
        "2",
        "1e-2",
        "[]",
        "{}",
        "[1, 2]",
        "[[1, 2], [3, 4]]",
        "[nan, inf, -inf]",
        "{ k = 1.0 }",
        "true",
        "false",
        "\"\"",
        "''",
        "\"top-left\"",
        "\"16x16\"",
        "\"0x0\"",
        "\"4096x4096\"",
        "\"2x2\"",
        "\"512x512\"",
        "\"513x2\"",
        "\" 16 X 16 \"",
        "\"100pts\"",
        "\"85\"",
        "\"explicit_euler\"",
        "\"symplectic_euler\"",
        "\"rk4\"",
        "\"implicit_euler\"",
        "\"surface\"",
        "\"cloth\"",
        "\"same\"",
        "\"fit\"",
        "\"vertical\"",
        "\"per_node\"",
        "\"ramp\"",
        "\"pulse\"",
        "\"sine\"",
        "\"linear\"",
        "\"bottom-right\"",
        "\"shear\"",
        "[\"bend\", \"bend\"]",
        "\"config/scenes/hanging.toml\"",
        "\"config/surfaces/sphere-pulled.toml\"",
        "\"config\"",
        "\"Cargo.toml\"",
        "\"/dev/null\"",
        "1979-05-27T07:32:00Z",
        "0x7fffffff",
        "ply",
        "end_header",
        "element",
        "list",
    ]);
    prop_oneof![
        4 => fixed.prop_map(str::to_string),
        1 => any::<f64>().prop_map(toml_float),
        1 => any::<i64>().prop_map(|i| i.to_string()),
        // A TOML literal string of random unicode, and the same unquoted.
        1 => "[^'\\p{Cc}]{0,16}".prop_map(|s| format!("'{s}'")),
        1 => "\\PC{0,16}",
        // Nested arrays and inline tables, past the TOML parser's depth limit.
        1 => (1usize..200).prop_map(|d| format!("{}{}", "[".repeat(d), "]".repeat(d))),
        1 => (1usize..200).prop_map(|d| format!("{}1{}", "{ a = ".repeat(d), " }".repeat(d))),
    ]
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let long = prop::sample::select(vec![
        "a",
        "1",
        "9.",
        " ",
        "[",
        "{a=",
        "#",
        "é",
        "\u{1F600}",
        "\0",
        "\"",
        "x = 1\n",
    ]);
    prop_oneof![
        3 => (any::<Index>(), 0u8..8).prop_map(|(i, b)| Mutation::FlipBit(i, b)),
        2 => (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Mutation::SetByte(i, b)),
        2 => any::<Index>().prop_map(Mutation::Truncate),
        2 => any::<Index>().prop_map(Mutation::DeleteLine),
        2 => any::<Index>().prop_map(Mutation::DuplicateLine),
        1 => any::<Index>().prop_map(Mutation::DuplicateTable),
        6 => (any::<Index>(), value()).prop_map(|(i, v)| Mutation::ReplaceValue(i, v)),
        2 => (any::<Index>(), number()).prop_map(|(i, v)| Mutation::ReplaceNumber(i, v)),
        2 => (any::<Index>(), any::<String>()).prop_map(|(i, s)| Mutation::Insert(i, s)),
        1 => (any::<Index>(), long, 1usize..20_000).prop_map(|(i, u, n)| Mutation::LongLine(i, u, n)),
    ]
}

/// How `ReplaceValue` and `ReplaceNumber` find what they replace.
#[derive(Debug, Clone, Copy)]
enum Syntax {
    Toml,
    Tokens,
}

/// Byte ranges of the lines of `b`, each with its `\n`.
fn lines(b: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &c) in b.iter().enumerate() {
        if c == b'\n' {
            out.push(start..i + 1);
            start = i + 1;
        }
    }
    if start < b.len() {
        out.push(start..b.len());
    }
    out
}

/// Byte ranges of the values of TOML `key = value` pairs (top level, in
/// tables and in inline tables), outside comments and strings.
fn toml_values(b: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let (mut i, mut quote, mut comment) = (0, None, false);
    while i < b.len() {
        let c = b[i];
        match (comment, quote) {
            (true, _) if c == b'\n' => comment = false,
            (true, _) => {}
            (false, Some(q)) if c == q => quote = None,
            (false, Some(_)) if c == b'\\' => i += 1,
            (false, Some(_)) => {}
            (false, None) if c == b'#' => comment = true,
            (false, None) if c == b'"' || c == b'\'' => quote = Some(c),
            (false, None) if c == b'=' => {
                let mut s = i + 1;
                while s < b.len() && b[s] == b' ' {
                    s += 1;
                }
                let e = value_end(b, s);
                out.push(s..e);
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// End of the TOML value starting at `s`: a bracketed array or inline table
/// to its matching close, a string to its quote, else up to `,`, `}`, `]`,
/// `#` or the end of the line.
fn value_end(b: &[u8], s: usize) -> usize {
    match b.get(s) {
        Some(&open @ (b'[' | b'{')) => {
            let close = if open == b'[' { b']' } else { b'}' };
            let mut depth = 0usize;
            for (k, &c) in b.iter().enumerate().skip(s) {
                if c == open {
                    depth += 1;
                } else if c == close {
                    depth -= 1;
                    if depth == 0 {
                        return k + 1;
                    }
                } else if c == b'\n' && open == b'{' {
                    return k;
                }
            }
            b.len()
        }
        Some(&q @ (b'"' | b'\'')) => b[s + 1..]
            .iter()
            .position(|&c| c == q || c == b'\n')
            .map_or(b.len(), |k| s + 1 + k + 1),
        _ => b[s..]
            .iter()
            .position(|c| b",}]#\r\n".contains(c))
            .map_or(b.len(), |k| s + k),
    }
}

/// Byte ranges of TOML number literals (outside comments and strings): runs
/// of `[0-9a-z.+_-]` that start with a digit or a sign after a value
/// delimiter (`=`, `[`, `,`, `{` and spaces).
fn toml_numbers(b: &[u8]) -> Vec<std::ops::Range<usize>> {
    let literal = |c: u8| c.is_ascii_alphanumeric() || b".+-_".contains(&c);
    let mut out = Vec::new();
    let (mut i, mut quote, mut comment, mut after_delimiter) = (0, None, false, false);
    while i < b.len() {
        let c = b[i];
        match (comment, quote) {
            (true, _) => comment = c != b'\n',
            (false, Some(q)) if c == q => quote = None,
            (false, Some(_)) if c == b'\\' => i += 1,
            (false, Some(_)) => {}
            (false, None) if c == b'#' => comment = true,
            (false, None) if c == b'"' || c == b'\'' => quote = Some(c),
            (false, None) if after_delimiter && (c.is_ascii_digit() || c == b'-' || c == b'+') => {
                let end = b[i..].iter().position(|&c| !literal(c)).map_or(b.len(), |k| i + k);
                out.push(i..end);
                i = end;
                after_delimiter = false;
                continue;
            }
            _ => {}
        }
        after_delimiter = !comment && quote.is_none() && b"=[,{ ".contains(&c);
        i += 1;
    }
    out
}

/// Byte ranges of whitespace-separated tokens.
fn tokens(b: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &c) in b.iter().enumerate() {
        let space = c.is_ascii_whitespace();
        match (start, space) {
            (None, false) => start = Some(i),
            (Some(s), true) => {
                out.push(s..i);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push(s..b.len());
    }
    out
}

fn apply(b: &mut Vec<u8>, m: &Mutation, syntax: Syntax) {
    let at = |i: &Index, len: usize| if len == 0 { 0 } else { i.index(len) };
    match m {
        Mutation::FlipBit(i, bit) if !b.is_empty() => {
            let k = at(i, b.len());
            b[k] ^= 1 << bit;
        }
        Mutation::SetByte(i, byte) if !b.is_empty() => {
            let k = at(i, b.len());
            b[k] = *byte;
        }
        Mutation::Truncate(i) => b.truncate(at(i, b.len() + 1)),
        Mutation::DeleteLine(i) | Mutation::DuplicateLine(i) => {
            let ls = lines(b);
            if ls.is_empty() {
                return;
            }
            let r = ls[at(i, ls.len())].clone();
            if matches!(m, Mutation::DeleteLine(_)) {
                b.drain(r);
            } else {
                let copy = b[r.clone()].to_vec();
                b.splice(r.start..r.start, copy);
            }
        }
        Mutation::DuplicateTable(i) => {
            let ls = lines(b);
            let starts: Vec<usize> = (0..ls.len()).filter(|&k| b[ls[k].start] == b'[').collect();
            if starts.is_empty() {
                return;
            }
            let n = at(i, starts.len());
            let start = ls[starts[n]].start;
            let end = starts.get(n + 1).map_or(b.len(), |&k| ls[k].start);
            let mut copy = b[start..end].to_vec();
            if copy.last() != Some(&b'\n') {
                copy.insert(0, b'\n');
            }
            b.splice(end..end, copy);
        }
        Mutation::ReplaceValue(i, v) => {
            let spans = match syntax {
                Syntax::Toml => toml_values(b),
                Syntax::Tokens => tokens(b),
            };
            if !spans.is_empty() {
                let r = spans[at(i, spans.len())].clone();
                b.splice(r, v.bytes());
            }
        }
        Mutation::ReplaceNumber(i, v) => {
            let spans: Vec<_> = match syntax {
                Syntax::Toml => toml_numbers(b),
                Syntax::Tokens => tokens(b)
                    .into_iter()
                    .filter(|r| std::str::from_utf8(&b[r.clone()]).is_ok_and(|t| t.parse::<f64>().is_ok()))
                    .collect(),
            };
            if !spans.is_empty() {
                let r = spans[at(i, spans.len())].clone();
                b.splice(r, v.bytes());
            }
        }
        Mutation::Insert(i, s) => {
            let k = at(i, b.len() + 1);
            b.splice(k..k, s.bytes());
        }
        Mutation::LongLine(i, unit, count) => {
            let ls = lines(b);
            let k = if ls.is_empty() { 0 } else { ls[at(i, ls.len())].start };
            let mut line = unit.repeat(*count).into_bytes();
            line.push(b'\n');
            b.splice(k..k, line);
        }
        _ => {}
    }
}

/// One of `bases` with 1–3 numbers replaced (the syntax intact, so the
/// values reach validation: half the cases), or with 1–4 edits of any kind
/// (mostly syntax errors: three in eight), or random bytes (one in eight).
fn input(bases: usize) -> impl Strategy<Value = (usize, Vec<Mutation>, Option<Vec<u8>>)> {
    let replace = (any::<Index>(), number()).prop_map(|(i, v)| Mutation::ReplaceNumber(i, v));
    prop_oneof![
        4 => (0..bases, prop::collection::vec(replace, 1..4), Just(None)),
        3 => (0..bases, prop::collection::vec(mutation(), 1..5), Just(None)),
        1 => (Just(0), Just(Vec::new()), prop::collection::vec(any::<u8>(), 0..1024).prop_map(Some)),
    ]
}

fn mutated(base: &[u8], muts: &[Mutation], random: Option<Vec<u8>>, syntax: Syntax) -> Vec<u8> {
    match random {
        Some(bytes) => bytes,
        None => {
            let mut b = base.to_vec();
            for m in muts {
                apply(&mut b, m, syntax);
            }
            b
        }
    }
}

// ------------------------------------------------------------ predicates

/// Line numbers the message gives (`line N`, `Line N`, `lines N`), in order.
fn line_numbers(msg: &str) -> Vec<usize> {
    let lower = msg.to_lowercase();
    lower
        .match_indices("line")
        .filter_map(|(k, _)| {
            let rest = &lower[k + 4..];
            let rest = rest.strip_prefix("s ").or_else(|| rest.strip_prefix(' '))?;
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            digits.parse().ok()
        })
        .collect()
}

/// Number of lines of `text` as an editor counts them (a final line without
/// `\n` counts; an error may point one past the end).
fn line_count(b: &[u8]) -> usize {
    lines(b).len().max(1)
}

/// Whether `msg` names a line of the file (1 ..= lines + 1).
fn names_a_line(msg: &str, b: &[u8]) -> bool {
    line_numbers(msg).iter().any(|&n| (1..=line_count(b) + 1).contains(&n))
}

/// Whether `msg` says `line L, column C` with L a line of the file (TOML
/// errors and invalid UTF-8).
fn names_line_and_column(msg: &str, b: &[u8]) -> bool {
    let lower = msg.to_lowercase();
    lower.match_indices("line ").any(|(k, _)| {
        let rest = &lower[k + 5..];
        let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
        let line_ok = digits
            .parse()
            .is_ok_and(|n: usize| (1..=line_count(b) + 1).contains(&n));
        line_ok
            && rest[digits.len()..]
                .strip_prefix(", column ")
                .is_some_and(|c| c.starts_with(|d: char| d.is_ascii_digit()))
    })
}

/// Whether `problem` starts with `<field path>: ` whose first key is one of
/// `roots`: `key(\[digits\])*(\.key(\[digits\])*)*`.
fn starts_with_field_path(problem: &str, roots: &[&str]) -> bool {
    let Some((path, what)) = problem.split_once(": ") else {
        return false;
    };
    if what.trim().is_empty() {
        return false;
    }
    let key_ok = |k: &str| {
        !k.is_empty()
            && k.starts_with(|c: char| c.is_ascii_lowercase() || c == '_')
            && k.chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
    };
    path.split('.').enumerate().all(|(n, segment)| {
        let mut parts = segment.split('[');
        let key = parts.next().unwrap_or("");
        let indices_ok = parts.all(|p| {
            p.strip_suffix(']')
                .is_some_and(|d| !d.is_empty() && d.bytes().all(|c| c.is_ascii_digit()))
        });
        key_ok(key) && indices_ok && (n > 0 || roots.contains(&key))
    })
}

const SCENE_ROOTS: [&str; 11] = [
    "name",
    "description",
    "cloth",
    "springs",
    "material",
    "simulation",
    "strain",
    "pins",
    "forces",
    "wind",
    "colliders",
];
const CONFIG_ROOTS: [&str; 8] = [
    "prefix",
    "cache",
    "zenoh",
    "engine",
    "estimation",
    "instances",
    "snapshots",
    "http",
];

/// A refused scene: its message names the file and, for a parse error, a
/// line and column of it; for invalid values, every problem starts with its
/// field path.
fn check_scene_error(err: &SceneError, origin: &str, bytes: &[u8]) -> Result<(), TestCaseError> {
    let msg = err.to_string();
    prop_assert!(msg.contains(origin), "does not name {origin}: {msg}");
    match err {
        SceneError::Parse { message, .. } => {
            prop_assert!(
                names_line_and_column(message, bytes),
                "names no line and column of the file: {msg}"
            )
        }
        SceneError::Invalid { problems, .. } => {
            prop_assert!(!problems.is_empty(), "no problem listed: {msg}");
            for p in problems {
                prop_assert!(
                    starts_with_field_path(p, &SCENE_ROOTS),
                    "`{p}` names no field in: {msg}"
                );
            }
        }
        SceneError::Io { .. } => prop_assert!(false, "an existing file gave an I/O error: {msg}"),
        SceneError::Sim { .. } => prop_assert!(false, "loading built a simulation: {msg}"),
    }
    Ok(())
}

/// What validation promises about an accepted scene.
fn check_scene_valid(s: &Scene) -> Result<(), TestCaseError> {
    let positive = |x: f64| x.is_finite() && x > 0.0;
    let non_negative = |x: f64| x.is_finite() && x >= 0.0;
    prop_assert!(positive(s.width) && positive(s.height), "{} × {}", s.width, s.height);
    prop_assert!(positive(s.areal_density), "areal density {}", s.areal_density);
    prop_assert!(
        s.mesh.is_some() || (2..=4096).contains(&s.nx) && (2..=4096).contains(&s.ny),
        "{}×{}",
        s.nx,
        s.ny
    );
    let p = &s.params;
    prop_assert!(
        positive(p.dt) && positive(s.duration) && p.dt <= s.duration,
        "dt {} duration {}",
        p.dt,
        s.duration
    );
    for c in p.material.springs {
        prop_assert!(non_negative(c.k) && non_negative(c.c), "{c:?}");
    }
    prop_assert!(p.gravity.iter().all(|g| g.is_finite()), "{:?}", p.gravity);
    prop_assert!(non_negative(p.drag), "drag {}", p.drag);
    prop_assert!(positive(p.cg.tolerance) && p.cg.max_iterations >= 1, "{:?}", p.cg);
    if let Some(a) = p.stiffness_adjustment {
        prop_assert!(non_negative(a.allowed), "{a:?}");
    }
    if let Some(l) = p.strain_limit {
        prop_assert!(non_negative(l.max_strain) && non_negative(l.tolerance), "{l:?}");
        prop_assert!(
            l.max_iterations >= 1 && l.kinds.contains(&true),
            "a limit that never limits: {l:?}"
        );
    }
    Ok(())
}

/// An accepted scene built at a small resolution: a simulation with
/// positive masses whose dt is within the predicted limit unless forced, or
/// a refusal naming the file and the scene field behind it.
fn check_scene_builds(s: &Scene) -> Result<(), TestCaseError> {
    let level = match &s.mesh {
        Some(m) => Level::Vertices(m.reference.vertices().min(200)),
        None => Level::new(s.nx.min(12), s.ny.min(12)),
    };
    match s.build_level(level) {
        Ok(sim) => {
            prop_assert!(sim.masses().iter().all(|m| m.is_finite() && *m > 0.0));
            if s.stability == StabilityCheck::Enforce {
                prop_assert!(
                    sim.params().dt <= sim.dt_limit(),
                    "dt {} > limit {}",
                    sim.params().dt,
                    sim.dt_limit()
                );
            }
        }
        Err(e) => {
            let msg = e.to_string();
            prop_assert!(msg.contains(&s.origin), "does not name {}: {msg}", s.origin);
            match &e {
                SceneError::Invalid { problems, .. } => {
                    for p in problems {
                        prop_assert!(
                            starts_with_field_path(p, &SCENE_ROOTS),
                            "`{p}` names no field in: {msg}"
                        );
                    }
                }
                SceneError::Sim { .. } => {
                    let at = format!("at {level}: ");
                    let what = msg.split_once(&at).map_or("", |(_, w)| w);
                    prop_assert!(
                        starts_with_field_path(what, &SCENE_ROOTS),
                        "names no scene field: {msg}"
                    );
                }
                _ => prop_assert!(false, "unexpected refusal: {msg}"),
            }
        }
    }
    Ok(())
}

/// A refused config: the message names the file; a parse error names a
/// line and column; every invalid value is listed under its field path.
fn check_config_error(err: &ConfigError, origin: &str, text: &str) -> Result<(), TestCaseError> {
    let msg = err.to_string();
    prop_assert!(msg.contains(origin), "does not name {origin}: {msg}");
    match err {
        ConfigError::Parse { message, .. } => {
            prop_assert!(
                names_line_and_column(message, text.as_bytes()),
                "names no line and column of the file: {msg}"
            )
        }
        ConfigError::Invalid { problems, .. } => {
            prop_assert!(!problems.is_empty(), "no problem listed: {msg}");
            for p in problems {
                prop_assert!(
                    starts_with_field_path(p, &CONFIG_ROOTS),
                    "`{p}` names no field in: {msg}"
                );
            }
        }
        ConfigError::Io { .. } => prop_assert!(false, "parsing text gave an I/O error: {msg}"),
    }
    Ok(())
}

/// What validation promises about an accepted config.
fn check_config_valid(c: &ServiceConfig) -> Result<(), TestCaseError> {
    let e = &c.engine;
    prop_assert!(e.threads >= 1, "{e:?}");
    prop_assert!(e.max_catch_up > 0.0 && e.max_catch_up <= e.max_lag, "{e:?}");
    prop_assert!(e.max_lag.is_finite() && e.max_lag > 0.0, "{e:?}");
    prop_assert!(e.metrics_hz > 0.0 && e.metrics_hz <= 1000.0, "{e:?}");
    let s = &c.estimation;
    prop_assert!(
        s.spec.metric_stride >= 1 && s.spec.estimate_stride >= 2 && s.fit_frames >= 2,
        "{s:?}"
    );
    prop_assert!(
        u128::from(s.spec.frames) >= 3 * u128::from(s.spec.metric_stride),
        "{} reference steps do not cover 3 metric frames of {}",
        s.spec.frames,
        s.spec.metric_stride
    );
    prop_assert!(
        s.spec.estimate_stride <= s.spec.frames,
        "an estimate stride of {} records no sample in {} reference steps",
        s.spec.estimate_stride,
        s.spec.frames
    );
    prop_assert!(!c.instances.is_empty());
    for (i, inst) in c.instances.iter().enumerate() {
        prop_assert!(
            lodcloth::service::config::valid_instance_name(&inst.name),
            "{:?}",
            inst.name
        );
        prop_assert!(
            c.instances[..i].iter().all(|o| o.name != inst.name),
            "{:?} twice",
            inst.name
        );
        prop_assert!(
            !inst.levels.is_empty() && inst.levels.contains(&inst.start),
            "{:?}",
            inst.levels
        );
        if let Some(dt) = inst.dt {
            prop_assert!(dt.is_finite() && dt > 0.0, "dt {dt}");
        }
        prop_assert!(
            inst.publish_hz > 0.0 && inst.publish_hz <= 1000.0,
            "{}",
            inst.publish_hz
        );
        if let InstanceKind::Cloth(scene) = &inst.kind {
            check_scene_valid(scene)?;
            for l in &inst.levels {
                match (&scene.mesh, l) {
                    // A mesh cloth's levels are vertex counts its chain makes.
                    (Some(mesh), Level::Vertices(n)) => {
                        prop_assert!(
                            *n >= 3 && *n <= mesh.reference.vertices(),
                            "{l} of a {}-vertex mesh",
                            mesh.reference.vertices()
                        );
                        prop_assert!(scene.cloth_level(*l).is_ok(), "{l} cannot be made");
                    }
                    (None, Level::Grid { nx, ny }) => prop_assert!(
                        *nx >= 2 && *ny >= 2 && *nx <= scene.nx && *ny <= scene.ny,
                        "{l} in {}x{}",
                        scene.nx,
                        scene.ny
                    ),
                    _ => return Err(TestCaseError::fail(format!("{l} is not a level of {}", scene.name))),
                }
            }
        }
    }
    Ok(())
}

/// A refused cloud: the message names the file and, for XYZ, a line of it
/// (or says the file has no points); for PLY, the header line, or the
/// element, property or vertex at fault.
fn check_cloud_error(err: &io::PointsIoError, name: &str, bytes: &[u8]) -> Result<(), TestCaseError> {
    let msg = err.to_string();
    prop_assert!(msg.contains(name), "does not name {name}: {msg}");
    let io::PointsIoError::Invalid { message, .. } = err else {
        return Err(TestCaseError::fail(format!("not a content error: {msg}")));
    };
    if name.ends_with(".ply") {
        prop_assert!(message.starts_with("PLY "), "{msg}");
        let names_part = ["vertex", "element", "property"].iter().any(|w| message.contains(w));
        prop_assert!(
            names_a_line(message, bytes) || names_part,
            "names no line, element or property: {msg}"
        );
    } else {
        prop_assert!(
            (message.starts_with("line ") && names_a_line(message, bytes)) || message.starts_with("no points"),
            "does not start with a line of the file: {msg}"
        );
    }
    Ok(())
}

fn check_cloud_valid(c: &PointCloud) -> Result<(), TestCaseError> {
    prop_assert!(!c.positions.is_empty());
    prop_assert!(c.positions.iter().flatten().all(|x| x.is_finite()));
    if let Some(n) = &c.normals {
        prop_assert_eq!(n.len(), c.positions.len());
        for v in n {
            let l2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            prop_assert!((l2 - 1.0).abs() < 1e-9, "normal {v:?} is not unit");
        }
    }
    Ok(())
}

// ------------------------------------------------------------- fuzzing

/// Cases per parser: 56,000 inputs; the whole file takes 6–10 s on two
/// cores in `--release` (measured with other builds running alongside).
/// `LODCLOTH_FUZZ_SCALE=k` runs k times as many, for a longer search.
const SCENE_CASES: u32 = 8_000;
const CONFIG_CASES: u32 = 16_000;
const CLOUD_CASES: u32 = 32_000;

/// Runs `test` on `cases` × `LODCLOTH_FUZZ_SCALE` inputs drawn from
/// `strategy` (a fresh seed each run), handing it a scratch directory shared
/// by the cases: making a directory per case costs more than the parse. A
/// failure panics with the smallest failing input proptest found; add it as
/// a regression test below.
fn fuzz<S: Strategy>(cases: u32, strategy: S, test: impl Fn(S::Value, &Path) -> Result<(), TestCaseError>) {
    let scale = std::env::var("LODCLOTH_FUZZ_SCALE")
        .ok()
        .and_then(|s| s.parse::<u32>().ok())
        .unwrap_or(1);
    let config = ProptestConfig {
        cases: cases.saturating_mul(scale),
        failure_persistence: None,
        ..ProptestConfig::default()
    };
    let dir = tempfile::tempdir().expect("temporary directory");
    let mut runner = proptest::test_runner::TestRunner::new(config);
    if let Err(e) = runner.run(&strategy, |value| test(value, dir.path())) {
        panic!("{e}");
    }
}

/// Writes `bytes` to `dir/name`, runs `read` on the path, removes the file.
fn with_file<T>(dir: &Path, name: &str, bytes: &[u8], read: impl FnOnce(&Path) -> T) -> T {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write");
    let out = read(&path);
    std::fs::remove_file(&path).expect("remove");
    out
}

/// Scene files (through `Scene::load`, so invalid UTF-8 is covered):
/// refusals name the file and the line or field; accepted scenes are
/// physically valid and build (or are refused by name) at a small size.
#[test]
fn mutated_scenes_never_panic_and_every_refusal_names_file_and_field() {
    fuzz(SCENE_CASES, input(4), |(base, muts, random), dir| {
        let bases = scenes();
        let bytes = mutated(bases[base % bases.len()].1.as_bytes(), &muts, random, Syntax::Toml);
        let origin = dir.join("fuzz-scene.toml").display().to_string();
        match with_file(dir, "fuzz-scene.toml", &bytes, Scene::load) {
            Ok(scene) => {
                check_scene_valid(&scene)?;
                check_scene_builds(&scene)
            }
            Err(e) => check_scene_error(&e, &origin, &bytes),
        }
    });
}

/// Service configs (as text; scene paths resolve from the crate directory,
/// where the tests run): refusals name the file and the line or field;
/// accepted configs are valid.
#[test]
fn mutated_configs_never_panic_and_every_refusal_names_file_and_field() {
    fuzz(CONFIG_CASES, input(8), |(base, muts, random), _| {
        let bases = configs();
        // Most cases on the one-instance config (the last): the shipped
        // ones load five scenes and a 3,203-point cloud each time.
        let which = base.min(bases.len() - 1);
        let bytes = mutated(bases[which].1.as_bytes(), &muts, random, Syntax::Toml);
        let text = String::from_utf8_lossy(&bytes);
        let origin = "fuzz-config.toml";
        match ServiceConfig::from_toml(&text, origin) {
            Ok(config) => check_config_valid(&config),
            Err(e) => check_config_error(&e, origin, &text),
        }
    });
}

/// Point clouds (XYZ and PLY ascii, binary little and big endian): refusals
/// name the file and the line, element or property; accepted clouds have
/// finite points and unit normals.
#[test]
fn mutated_clouds_never_panic_and_every_refusal_names_file_and_place() {
    fuzz(
        CLOUD_CASES,
        (input(7), any::<bool>()),
        |((base, muts, random), as_other), dir| {
            let bases = clouds();
            let (name, original) = &bases[base % bases.len()];
            let bytes = mutated(original, &muts, random, Syntax::Tokens);
            // Also read as the other format (random bytes go to both).
            let name = match (as_other, name.ends_with(".ply")) {
                (false, _) => *name,
                (true, true) => "other.xyz",
                (true, false) => "other.ply",
            };
            match with_file(dir, name, &bytes, io::read) {
                Ok(cloud) => check_cloud_valid(&cloud),
                Err(e) => check_cloud_error(&e, name, &bytes),
            }
        },
    );
}

// ------------------------------------------------- physics refusals

/// A valid scene to break: 12×6, light cotton, top edge pinned.
const VALID_SCENE: &str = r#"
name = "valid"

[cloth]
width = 1.0
height = 0.5
nx = 12
ny = 6
areal_density = 0.2

[springs]
structural = { k = 400.0, c = 0.04 }
shear = { k = 60.0, c = 0.006 }
bend = { k = 8.0, c = 0.0008 }

[simulation]
integrator = "explicit_euler"
dt = 1e-5
duration = 1.0

[[pins]]
nodes = { edge = "top" }
"#;

/// The problems of a scene refused at validation.
fn scene_problems(text: &str) -> Vec<String> {
    match Scene::from_toml(text, "refused.toml") {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(SceneError::Invalid { origin, problems }) => {
            assert_eq!(origin, "refused.toml");
            problems
        }
        Err(other) => panic!("refused, but not as invalid values: {other}"),
    }
}

/// `text` refused with exactly one problem, which starts with `field: ` and says `reason`.
fn assert_one_problem(text: &str, field: &str, reason: &str) {
    let problems = scene_problems(text);
    assert_eq!(problems.len(), 1, "{problems:#?}");
    let p = &problems[0];
    assert!(
        p.starts_with(&format!("{field}: ")),
        "`{p}` does not start with {field}"
    );
    assert!(p.contains(reason), "`{p}` does not say `{reason}`");
}

#[test]
fn the_valid_scene_builds_with_explicit_euler() {
    Scene::from_toml(VALID_SCENE, "valid.toml")
        .expect("valid")
        .build()
        .expect("builds");
}

#[test]
fn negative_stiffness_is_refused_naming_the_spring_kind() {
    for (kind, from, to) in [
        ("structural", "k = 400.0", "k = -400.0"),
        ("shear", "k = 60.0", "k = -60.0"),
        ("bend", "k = 8.0", "k = -1e-9"),
    ] {
        let text = VALID_SCENE.replace(from, to);
        assert_one_problem(&text, &format!("springs.{kind}.k"), "must be finite and ≥ 0, got -");
    }
}

#[test]
fn zero_negative_and_nan_areal_density_are_refused() {
    for value in ["0.0", "-0.2", "nan", "inf"] {
        let text = VALID_SCENE.replace("areal_density = 0.2", &format!("areal_density = {value}"));
        assert_one_problem(&text, "cloth.areal_density", "must be positive and finite");
    }
}

#[test]
fn zero_negative_and_nan_dt_are_refused() {
    for value in ["0.0", "-0.0", "-1e-5", "nan", "-inf"] {
        let text = VALID_SCENE.replace("dt = 1e-5", &format!("dt = {value}"));
        assert_one_problem(&text, "simulation.dt", "must be positive and finite");
    }
}

#[test]
fn dt_beyond_the_explicit_euler_limit_is_refused_at_build_unless_forced() {
    // 1e-2 s is far beyond explicit Euler's limit for this cloth (~1e-4 s);
    // the limit depends on the resolution, so the scene parses and building
    // it refuses.
    let text = VALID_SCENE.replace("dt = 1e-5", "dt = 1e-2");
    let scene = Scene::from_toml(&text, "unstable.toml").expect("an unstable dt still parses");
    let err = scene.build().map(|_| ()).expect_err("unstable dt");
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(
        matches!(
            err,
            SceneError::Sim {
                source: SimError::UnstableTimeStep { .. },
                ..
            }
        ),
        "{err:?}"
    );
    for want in [
        "unstable.toml",
        "simulation.dt: ",
        "beyond the predicted stability limit of explicit_euler",
    ] {
        assert!(msg.contains(want), "`{msg}` does not say `{want}`");
    }
    assert!(msg.contains("force_unstable"), "`{msg}` does not say how to force it");

    let forced = text.replace("duration = 1.0", "duration = 1.0\nforce_unstable = true");
    let scene = Scene::from_toml(&forced, "forced.toml").expect("parses");
    assert_eq!(scene.stability, StabilityCheck::Force);
    let sim = scene.build().expect("forced builds");
    assert!(
        sim.params().dt > sim.dt_limit(),
        "the test's dt must really be unstable"
    );
}

/// The small config with `instances[0]` edited.
fn config_with(from: &str, to: &str) -> String {
    assert!(SMALL_CONFIG.contains(from), "{from}");
    SMALL_CONFIG.replace(from, to)
}

#[test]
fn instance_dt_that_is_not_positive_and_finite_is_refused_by_path() {
    ServiceConfig::from_toml(SMALL_CONFIG, "small.toml").expect("the small config is valid");
    for value in ["0.0", "-1e-4", "nan", "inf"] {
        let err = ServiceConfig::from_toml(&config_with("dt = 1e-4", &format!("dt = {value}")), "small.toml")
            .map(|_| ())
            .expect_err(value);
        let ConfigError::Invalid { problems, .. } = &err else {
            panic!("{value}: refused, but not as invalid values: {err}");
        };
        assert_eq!(problems.len(), 1, "{problems:#?}");
        assert!(problems[0].starts_with("instances[0].dt: "), "{problems:#?}");
        assert!(problems[0].contains("must be positive and finite"), "{problems:#?}");
    }
}

/// A switch's settling step must be a time in (0, 1] s, and a surface has
/// no cloth shape to settle: each refused naming the instance's field.
#[test]
fn a_switch_settle_that_is_not_a_time_or_on_a_surface_is_refused_by_path() {
    for value in ["0.0", "-0.01", "nan", "2.0"] {
        let text = config_with("switch_settle = 0.0167", &format!("switch_settle = {value}"));
        let err = ServiceConfig::from_toml(&text, "small.toml")
            .map(|_| ())
            .expect_err(value);
        let ConfigError::Invalid { problems, .. } = &err else {
            panic!("{value}: refused, but not as invalid values: {err}");
        };
        assert_eq!(problems.len(), 1, "{problems:#?}");
        assert!(problems[0].starts_with("instances[0].switch_settle: "), "{problems:#?}");
    }
    let surface =
        "[[instances]]\nname = \"sphere\"\nkind = \"surface\"\nscene = \"config/surfaces/sphere-pulled.toml\"\n\
                   levels = [85, 327]\nstart = 85\nswitch_settle = 0.01\n";
    let text = format!("{SMALL_CONFIG}\n{surface}");
    let err = ServiceConfig::from_toml(&text, "small.toml")
        .map(|_| ())
        .expect_err("a surface");
    let ConfigError::Invalid { problems, .. } = &err else {
        panic!("refused, but not as invalid values: {err}");
    };
    assert!(
        problems.len() == 1 && problems[0].starts_with("instances[1].switch_settle: a surface"),
        "{problems:#?}"
    );
}

/// An instance's `contact` turns a cloth scene's self-contact on with its
/// thickness and friction (the levels and the reference get it through
/// the scene); a bad value, a thickness without `self = true`, and a
/// surface's `contact` are each refused naming the field.
#[test]
fn an_instance_contact_sets_self_contact_and_bad_ones_are_refused_by_path() {
    use lodcloth::plan::InstanceKind;
    let text = config_with(
        "switch_settle = 0.0167",
        "contact = { self = true, thickness = 0.004, friction = 0.2 }",
    );
    let config = ServiceConfig::from_toml(&text, "small.toml").expect("a valid contact");
    let InstanceKind::Cloth(scene) = &config.instances[0].kind else {
        panic!("the hanging instance is a cloth");
    };
    let contact = scene.params.self_contact.expect("self-contact on");
    assert_eq!((contact.thickness, contact.friction), (0.004, 0.2));
    for (table, field) in [
        ("{ self = true, thickness = 0.0 }", "instances[0].contact.thickness: "),
        ("{ self = true, friction = -1.0 }", "instances[0].contact.friction: "),
        (
            "{ thickness = 0.004 }",
            "instances[0].contact: thickness and friction describe self-contact",
        ),
    ] {
        let text = config_with("switch_settle = 0.0167", &format!("contact = {table}"));
        let err = ServiceConfig::from_toml(&text, "small.toml")
            .map(|_| ())
            .expect_err(table);
        let ConfigError::Invalid { problems, .. } = &err else {
            panic!("{table}: refused, but not as invalid values: {err}");
        };
        assert!(
            problems.len() == 1 && problems[0].starts_with(field),
            "{table}: {problems:#?}"
        );
    }
    let surface =
        "[[instances]]\nname = \"sphere\"\nkind = \"surface\"\nscene = \"config/surfaces/sphere-pulled.toml\"\n\
                   levels = [85, 327]\nstart = 85\ncontact = { self = true }\n";
    let err = ServiceConfig::from_toml(&format!("{SMALL_CONFIG}\n{surface}"), "small.toml")
        .map(|_| ())
        .expect_err("a surface");
    let ConfigError::Invalid { problems, .. } = &err else {
        panic!("refused, but not as invalid values: {err}");
    };
    assert!(
        problems.len() == 1 && problems[0].starts_with("instances[1].contact: self-contact is a cloth's"),
        "{problems:#?}"
    );
}

/// The config load does not know a level's stability limit (it depends on
/// the coefficients the level is prepared with), so an instance `dt` beyond
/// it loads; the engine refuses it when the instance starts. (The quick
/// start of a cloth returns `PrepareError::Failed` carrying the simulation's
/// refusal, which names `dt` and the limit but not `instances[0].dt`.)
#[test]
fn instance_dt_beyond_the_limit_loads_and_the_quick_start_refuses_it() {
    let text = config_with("dt = 1e-4", "dt = 1e-2");
    let config = ServiceConfig::from_toml(&text, "small.toml").expect("the config load does not check stability");
    let instance = Arc::new(config.instances[0].clone());
    assert_eq!(instance.dt, Some(1e-2));
    let preparer = Preparer::new(instance, config.estimation, None);
    let err = preparer.quick_start().map(|_| ()).expect_err("dt = 1e-2 is unstable");
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(
        matches!(err, PrepareError::Unstable { .. } | PrepareError::Failed { .. }),
        "{err:?}"
    );
    assert!(msg.contains("dt = 1e-2"), "{msg}");
    assert!(msg.contains("stability limit"), "{msg}");
}

#[test]
fn a_metric_stride_whose_triple_overflows_is_refused() {
    // 3 × 6148914691236517206 is 2^64 + 2: wrapping arithmetic would let
    // 600 reference steps "cover" three frames.
    let text = config_with("metric_stride = 40", "metric_stride = 6148914691236517206");
    let err = ServiceConfig::from_toml(&text, "small.toml")
        .map(|_| ())
        .expect_err("huge stride");
    let msg = err.to_string();
    assert!(
        msg.contains("estimation.reference_steps: 600 must cover at least 3 metric frames"),
        "{msg}"
    );
}

// ------------------------------------- regressions found by the fuzzing

#[test]
fn a_scene_with_invalid_utf8_is_refused_naming_line_and_column() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("latin1.toml");
    // "é" in Latin-1 on line 2, after `name = "caf`.
    let mut bytes = VALID_SCENE.replace("name = \"valid\"", "name = \"caf?\"").into_bytes();
    let at = bytes.iter().position(|&b| b == b'?').expect("marker");
    bytes[at] = 0xe9;
    std::fs::write(&path, &bytes).expect("write");
    let err = Scene::load(&path).map(|_| ()).expect_err("invalid UTF-8");
    let msg = err.to_string();
    assert!(matches!(err, SceneError::Parse { .. }), "{err:?}");
    assert!(msg.contains("latin1.toml"), "{msg}");
    assert!(msg.contains("line 2, column 12: not valid UTF-8 (byte 0xe9)"), "{msg}");
}

/// Writes `bytes` as `name` and reads it back as a cloud.
fn read_cloud(name: &str, bytes: &[u8]) -> Result<PointCloud, io::PointsIoError> {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).expect("write");
    io::read(&path)
}

#[test]
fn an_xyz_file_with_invalid_utf8_is_refused_naming_the_line() {
    let msg = read_cloud("latin1.xyz", b"0 0 0\n1 1 1 # caf\xe9\n")
        .map(|_| ())
        .expect_err("invalid UTF-8")
        .to_string();
    assert!(
        msg.contains("latin1.xyz: line 2, column 12: not valid UTF-8 (byte 0xe9)"),
        "{msg}"
    );
}

#[test]
fn huge_and_subnormal_normals_are_directions_not_zero() {
    let xyz = read_cloud("n.xyz", b"0 0 0 1e300 -1e300 0\n1 0 0 0 5e-324 0\n").expect("reads");
    let normals = xyz.normals.expect("normals");
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!((normals[0][0] - h).abs() < 1e-15 && (normals[0][1] + h).abs() < 1e-15 && normals[0][2] == 0.0);
    assert_eq!(normals[1], [0.0, 1.0, 0.0]);
    let ply = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\n\
        property double nx\nproperty double ny\nproperty double nz\nend_header\n0 0 0 0 0 -1e308\n";
    assert_eq!(
        read_cloud("n.ply", ply).expect("reads").normals,
        Some(vec![[0.0, 0.0, -1.0]])
    );
    // A zero normal is still refused.
    let msg = read_cloud("zero.xyz", b"0 0 0 0 0 0\n")
        .map(|_| ())
        .expect_err("zero")
        .to_string();
    assert!(msg.contains("line 1: normal (nx, ny, nz) is zero"), "{msg}");
}

#[test]
fn ply_header_errors_name_a_line() {
    for (bytes, want) in [
        (&b""[..], "PLY header: Line 1: "),
        (b"ply\nformat ascii 1.0\ncomment caf\xe9\n", "PLY header: Line 3: "),
        (
            b"ply\nelement vertex 1\nproperty float x\nend_header\n0\n",
            "PLY header, lines 1 to 4: No format line found",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            "PLY vertex element is empty (`element vertex 0`)",
        ),
    ] {
        let msg = read_cloud("h.ply", bytes).map(|_| ()).expect_err(want).to_string();
        assert!(msg.contains("h.ply: ") && msg.contains(want), "`{msg}` does not say `{want}`");
    }
}

#[test]
fn a_strain_limit_that_never_limits_is_refused() {
    let limit = "[strain.limit]\nmax_strain = 0.1\n";
    for (extra, field, reason) in [
        (
            "max_iterations = 0\n",
            "strain.limit.max_iterations",
            "must be at least 1",
        ),
        ("kinds = []\n", "strain.limit.kinds", "limits no spring"),
    ] {
        let text = format!("{VALID_SCENE}\n{limit}{extra}");
        assert_one_problem(&text, field, reason);
    }
    Scene::from_toml(
        &format!("{VALID_SCENE}\n{limit}max_iterations = 1\nkinds = [\"bend\"]\n"),
        "ok.toml",
    )
    .expect("a limit of bend springs with one sweep is valid");
}

#[test]
fn a_ramp_that_never_ends_is_refused() {
    let force = "[[forces]]\nnodes = { edge = \"bottom\" }\ntotal = [0.0, -1.0, 0.0]\n";
    for end in ["inf", "nan"] {
        let text = format!("{VALID_SCENE}\n{force}profile = {{ kind = \"ramp\", start = 0.0, end = {end} }}\n");
        assert_one_problem(&text, "forces[0].profile.end", "must be a finite number");
    }
}

#[test]
fn node_masses_that_underflow_are_refused_naming_the_areal_density() {
    // Positive, so valid on its own; × a node's area it rounds to 0 kg.
    let text = VALID_SCENE.replace("areal_density = 0.2", "areal_density = 5e-324");
    let scene = Scene::from_toml(&text, "light.toml").expect("a positive density parses");
    let msg = scene.build().map(|_| ()).expect_err("zero masses").to_string();
    assert!(msg.contains("light.toml"), "{msg}");
    assert!(msg.contains("cloth.areal_density: masses["), "{msg}");
    assert!(msg.contains("must be positive and finite"), "{msg}");
}
