//! Why a scene could not be loaded or built ([`SceneError`]), and how each
//! cause is worded: the scene field behind a value the simulation refused,
//! and where a file stops being UTF-8.

use crate::sim::SimError;

/// Why a scene could not be loaded or built.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene file {path}: {source}")]
    Io {
        /// The file's path, as given.
        path: String,
        /// What the operating system reported.
        source: std::io::Error,
    },
    /// The file is not UTF-8, or the TOML is malformed or has unknown/mistyped
    /// fields (the message names the line and column, and the key).
    #[error("scene {origin}: {message}")]
    Parse {
        /// The file's path, or the name the caller gave the text.
        origin: String,
        /// What is wrong and where: line, column and, for TOML, the key.
        message: String,
    },
    /// The values parsed but are invalid; every problem is listed with its path.
    #[error("scene {origin} is invalid:\n  - {}", problems.join("\n  - "))]
    Invalid {
        /// The file's path, or the name the caller gave the text.
        origin: String,
        /// One line per problem, each starting with its field path (e.g.
        /// `springs.structural.k: …`), in the order the fields are checked.
        problems: Vec<String>,
    },
    /// The simulation refused the built scene (e.g. an unstable dt); the
    /// message names the scene field behind the refused value.
    #[error("scene {origin} at {level}: {}{source}{}", sim_field(source), sim_hint(source))]
    Sim {
        /// The file's path, or the name the caller gave the text.
        origin: String,
        /// The refused build's level (`32x32`, a grid; `1200v`, a mesh).
        level: String,
        /// The simulation's reason.
        source: SimError,
    },
}

/// The scene field behind a value the simulation refused, as a message prefix.
/// Validation has already checked every field the simulation checks, except
/// what only the resolution decides: node masses (areal density × a node's
/// area, which can underflow or overflow) and the stability limit of dt.
fn sim_field(e: &SimError) -> &'static str {
    match e {
        SimError::UnstableTimeStep { .. } => "simulation.dt: ",
        SimError::InvalidParameter { name, .. } if name.starts_with("masses") => "cloth.areal_density: ",
        _ => "",
    }
}

/// How a scene forces an unstable dt (the simulation's message says "force it").
fn sim_hint(e: &SimError) -> &'static str {
    match e {
        SimError::UnstableTimeStep { .. } => " (simulation.force_unstable = true)",
        _ => "",
    }
}

/// Where the first invalid UTF-8 byte of `bytes` is, for a message:
/// `line L, column C: not valid UTF-8 (byte 0xXX)`.
pub(super) fn utf8_problem(bytes: &[u8], e: std::str::Utf8Error) -> String {
    let good = &bytes[..e.valid_up_to()];
    let line = good.iter().filter(|&&b| b == b'\n').count() + 1;
    let line_start = good.iter().rposition(|&b| b == b'\n').map_or(0, |k| k + 1);
    // Valid up to here, so the line so far is text.
    let column = String::from_utf8_lossy(&good[line_start..]).chars().count() + 1;
    format!(
        "line {line}, column {column}: not valid UTF-8 (byte 0x{:02x})",
        bytes[e.valid_up_to()]
    )
}
