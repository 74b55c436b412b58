//! The per-step CSV report of a simulation run.

use crate::sim::{SpringKind, StepReport};

/// Header line of the per-frame CSV report.
pub const REPORT_CSV_HEADER: &str = "step,time_s,kinetic_j,elastic_j,gravity_j,total_j,max_strain_structural,max_strain_shear,max_strain_bend,finite,solver_iterations,solver_residual,strain_iterations";

/// One CSV line for a report (matches [`REPORT_CSV_HEADER`]).
pub fn report_csv_line(r: &StepReport) -> String {
    format!(
        "{},{:.6},{:.9e},{:.9e},{:.9e},{:.9e},{:.6e},{:.6e},{:.6e},{},{},{:.3e},{}",
        r.step,
        r.time,
        r.kinetic_energy,
        r.elastic_energy,
        r.gravity_energy,
        r.total_energy(),
        r.max_strain[SpringKind::Structural.index()],
        r.max_strain[SpringKind::Shear.index()],
        r.max_strain[SpringKind::Bend.index()],
        r.finite,
        r.solver_iterations,
        r.solver_residual,
        r.strain_iterations
    )
}
