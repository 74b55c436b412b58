//! The core's tests: simulation, estimation, scenes and the coefficient
//! cache, built and linked without zenoh. One test binary, so the release
//! build links (thin LTO) the crate once rather than once per file.
//!
//! `cargo test --release -p lodcloth-core --test core` (one file: `--test core energy::`).

// The files name the crate `lodcloth`, as the root package re-exports it.
extern crate lodcloth_core as lodcloth;

mod common;
// Bent-plate fixtures, shared with the lab's stencil tests (not with the
// root package's tests, which include `common` too).
#[path = "common/plate.rs"]
mod plate;

mod bending;
mod cache;
mod conservation;
mod contact;
mod convergence;
mod drape;
mod energy;
mod equilibrium;
mod estimation;
mod kernel;
mod membrane;
mod mesh;
mod oscillator;
mod precision;
mod scenes;
mod selfcontact;
mod stability;
mod strain_control;
mod symmetry_determinism;
mod touch;
mod two_threads;
mod xpbd;
