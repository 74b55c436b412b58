//! The per-step CSV report of a simulation run.

use crate::sim::{SpringKind, StepReport};

/// Columns of the per-frame CSV report.
pub const REPORT_CSV_HEADER: [&str; 13] = [
    "step",
    "time_s",
    "kinetic_j",
    "elastic_j",
    "gravity_j",
    "total_j",
    "max_strain_structural",
    "max_strain_shear",
    "max_strain_bend",
    "finite",
    "solver_iterations",
    "solver_residual",
    "strain_iterations",
];

/// One CSV row for a report (matches [`REPORT_CSV_HEADER`]).
pub fn report_csv_row(r: &StepReport) -> [String; 13] {
    [
        r.step.to_string(),
        format!("{:.6}", r.time),
        format!("{:.9e}", r.kinetic_energy),
        format!("{:.9e}", r.elastic_energy),
        format!("{:.9e}", r.gravity_energy),
        format!("{:.9e}", r.total_energy()),
        format!("{:.6e}", r.max_strain[SpringKind::Structural.index()]),
        format!("{:.6e}", r.max_strain[SpringKind::Shear.index()]),
        format!("{:.6e}", r.max_strain[SpringKind::Bend.index()]),
        r.finite.to_string(),
        r.solver_iterations.to_string(),
        format!("{:.3e}", r.solver_residual),
        r.strain_iterations.to_string(),
    ]
}
