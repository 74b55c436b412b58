//! lodcloth: mass-spring cloth at several levels of detail, stepping in real
//! time, with behaviour kept coherent across levels.
//!
//! # Layout
//! Two crates; dependencies point one way:
//! `core ← engine ← service ← {view, foxglove_bridge, CLI}`, with `proto`
//! converting at the service's edge and `output` beside the service, on the
//! core alone. The lab (`crates/lodcloth-lab`: the studies, their charts and
//! notebook) depends on this crate, never the other way round.
//!
//! - The pure core, the `lodcloth-core` crate (`crates/lodcloth-core`),
//!   re-exported here under the same names: [`sim`], [`scene`], [`lod`],
//!   [`estimate`], [`points`], [`cache`], [`plan`] (what an instance is in
//!   domain types and how its levels are prepared), [`hash`], [`atomic`] and
//!   [`names`]. It depends on no async runtime, bus, web or plotting crate.
//! - [`engine`] — the only code that knows threads and the wall clock:
//!   instances stepping at fixed dt on OS threads, paced to real time;
//!   commands applied between steps; newest-value state and metrics out.
//!   It takes [`plan::InstancePlan`]s and never sees config or wire types.
//! - [`service`] — tokio + zenoh around the engine: config (validated into
//!   plans), publishers, queryables, liveliness, key expressions
//!   (`service::keys`), request checks, snapshots, and the client used by the
//!   CLI and tests.
//! - [`proto`] — the wire contract (`proto/lodcloth/v1/lodcloth.proto`) and
//!   every wire ↔ domain conversion.
//! - [`view`] and [`foxglove_bridge`] — clients of the bus: the browser view
//!   and the Foxglove WebSocket bridge.
//! - [`output`] — trajectory files, CSV reports, pictures (PNG render, SVG charts).
//! - [`args`] — the command-line pieces the lab's binary shares.
//! - `src/cli/` — the `lodcloth` command line: `serve` and its clients,
//!   `simulate`, `points`, `mesh`, `inspect`.
//!
//! `docs/architecture.md` walks through how a state and a switch request
//! flow through these layers.

pub use lodcloth_core::{
    atomic, cache, estimate, hash, level, lod, mesh, names, plan, points, problems, scene, sim, touch, turns,
};

/// `<package version> (<git revision>)`, e.g. `0.1.0 (d7aae52e1f3a)`: what
/// `lodcloth --version` prints and `lodcloth_build_info` reports. The
/// revision is HEAD's when built from a checkout (see `build.rs`).
pub const VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), " (", env!("LODCLOTH_GIT_REVISION"), ")");
/// The git revision alone (`unknown` when built without one).
pub const REVISION: &str = env!("LODCLOTH_GIT_REVISION");

pub mod args;
pub mod engine;
pub mod foxglove_bridge;
pub mod output;
pub mod proto;
pub mod service;
pub mod view;
