//! Files a run leaves behind: the binary trajectory (written and read back),
//! the inputs a recording holds (to replay), CSV tables (and the per-step
//! report), PNG renders of a cloth or a cloud, and SVG charts. One file per
//! format; the pictures share the camera (public for the lab's error maps).

pub mod camera;
mod chart;
mod csv_table;
mod render;
mod replay;
mod report;
mod trajectory;

use std::path::Path;

pub use chart::{line_chart_svg, line_chart_svg_legend, Series, PALETTE};
pub use csv_table::CsvTable;
pub use render::{render_png, render_points_png};
pub use replay::{recorded_inputs, Replay};
pub use report::{report_csv_row, REPORT_CSV_HEADER};
pub use trajectory::{Frame, Precision, TrajectoryHeader, TrajectoryReader, TrajectoryWriter, TRAJECTORY_MAGIC};

/// Errors from reading or writing output files.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{path}: not a trajectory file ({reason})")]
    Format { path: String, reason: String },
    #[error("{path}: no inputs to replay ({reason})")]
    Inputs { path: String, reason: String },
    #[error("{path}: cannot draw: {reason}")]
    Draw { path: String, reason: String },
}

/// Maps an I/O error on `path` to [`OutputError::Io`].
fn io_err(path: &Path) -> impl Fn(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.display().to_string(),
        source,
    }
}
