//! lodcloth: mass-spring cloth at several levels of detail, stepping in real
//! time, with behaviour kept coherent across levels.
//!
//! # Layout
//! Dependencies point one way: `main → {experiments, output, cache} →
//! estimate → {lod, scene} → sim` (`cache` also names `scene`'s mass
//! convention).
//!
//! - [`sim`] — the pure core: topology (springs by type in a fixed order),
//!   state (flat arrays), forces (Sung 2018 eq. 1), integrators (explicit,
//!   symplectic and implicit Euler, RK4), strain control, stability
//!   prediction. No I/O, no threads, no allocation per step.
//! - [`scene`] — scene files (TOML): cloth size and resolution, material,
//!   pins, forces over time, wind; validated into ready-to-run simulations at
//!   any resolution.
//! - [`lod`] — barycentric correlation between resolutions, state transfer.
//! - [`estimate`] — pure coefficient estimation (same, BCD, GKD, lsq, fit),
//!   reference recording and the error metric (Sung 2018 eq. 9).
//! - [`output`] — trajectory files, CSV reports, pictures (PNG render, SVG charts).
//! - [`cache`] — on-disk cache of estimated coefficients: one checksummed TOML
//!   file per (scene, resolutions, method, mass, integrator, dt), written
//!   atomically so a crash never leaves a torn file.
//! - [`experiments`] — longer studies built on the core (stability sweeps).
//! - [`engine`] — the only code that knows threads and the wall clock:
//!   instances stepping at fixed dt on OS threads, paced to real time;
//!   commands applied between steps; newest-value state and metrics out;
//!   level preparation (reference, estimate, calibration) off those threads.
//! - [`service`] — tokio + zenoh around the engine: config, publishers,
//!   queryables, liveliness, key expressions (`service::keys`), and the
//!   client used by the CLI and tests.
//! - [`proto`] — the wire contract (`proto/lodcloth/v1/lodcloth.proto`) and
//!   every wire ↔ domain conversion.
//! - `main.rs` — the `lodcloth` command line: `serve` and its clients,
//!   `simulate`, `experiment`, `stability`, `inspect`.

pub mod cache;
pub mod engine;
pub mod estimate;
pub mod experiments;
pub mod foxglove_bridge;
pub mod lod;
pub mod output;
pub mod points;
pub mod proto;
pub mod scene;
pub mod service;
pub mod sim;
pub mod view;
