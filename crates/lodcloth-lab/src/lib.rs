//! lodcloth's lab: the studies that measured and chose what the service
//! does, apart from the service. The product (`lodcloth`, `lodcloth-core`)
//! never depends on this crate.
//!
//! - [`experiments`] — the studies as functions returning values: Table 1
//!   of Sung et al. 2018 and its readings, Pareto fronts, level planning,
//!   switch continuity, the generalisation suite with its chaos floor,
//!   coherence under drags, stability sweeps.
//! - [`error_map`] — cloths side by side coloured by per-node error.
//! - [`modal`] — a level's bending stiffened mode by mode towards the
//!   reference's spectrum (explored for the Cusick drape, not shipped).
//! - [`stencils`] — bending stencil rules other than the scenes' (triangle
//!   patches, quartics, the mixed finite element Hessian), for measuring.
//! - The `lodcloth-lab` binary (`src/main.rs`, `src/cli/`) runs each study
//!   and writes its CSV, markdown and charts; `examples/` holds the drape
//!   scans and probes; `NOTEBOOK.md` is the dated record of what was tried.

pub mod error_map;
pub mod experiments;
pub mod modal;
pub mod stencils;
