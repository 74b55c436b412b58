//! lodcloth's pure core: everything that computes, nothing that serves.
//!
//! This crate depends on no async runtime, bus, web or plotting crate, so the
//! compiler keeps it pure; its tests and step benchmark build without zenoh.
//! Nothing here starts a thread of its own (the `fit` estimator and the
//! experiments use rayon's pool; a large cloth's step hands its second half
//! to a thread the caller lends, [`sim::Pair`]), reads a clock to pace
//! anything or allocates per step.
//!
//! # Layout
//! Dependencies point one way: `plan → {cache, estimate, points} → {lod,
//! scene} → mesh → sim`, with `hash` and `atomic` below everything that
//! writes or checks files. `sim` knows no mesh: a mesh level's topology
//! carries its nodes' material coordinates and reference vertices as plain
//! data ([`sim::MeshNodes`]), from which `mesh` reads the level's rest
//! surface ([`mesh::RestSurface`]) for live input and pin sets.
//!
//! - [`sim`] — the mass-spring cloth: topology (springs by type in a fixed
//!   order), state (flat arrays), forces (Sung 2018 eq. 1), integrators
//!   (explicit, symplectic and implicit Euler, RK4), strain control,
//!   stability prediction.
//! - [`scene`] — scene files (TOML): cloth size and resolution, material,
//!   pins, forces over time, wind; validated into ready-to-run simulations at
//!   any resolution.
//! - [`touch`] — live input (grabs, wind, pin moves, impulses) in material
//!   coordinates, resolved onto a simulation at any level (`touch → {scene,
//!   mesh, sim}`).
//! - [`level`] — a level of detail: a grid, a point count or a mesh's
//!   vertex count, as written in configs and on the command line.
//! - [`lod`] — barycentric correlation between resolutions, state transfer.
//! - [`estimate`] — coefficient estimation (same, BCD, GKD, lsq, fit, shape, follow, drape),
//!   reference recording and the error metric (Sung 2018 eq. 9).
//! - [`mesh`] — triangle-mesh cloths: OBJ, PLY and glTF files, springs on
//!   and across edges, level chains by quadric simplification, closest points
//!   on a rest surface, material points and patches on a level.
//! - [`points`] — point-sampled surfaces: I/O, normals, simplification,
//!   springs on tangent planes, MLS transfer back to every point.
//! - [`cache`] — on-disk cache of estimated coefficients, one checksummed
//!   TOML file per key.
//! - [`plan`] — what an instance is in domain types ([`plan::InstancePlan`],
//!   [`plan::Level`]) and how one of its levels is made ready: reference,
//!   stable dt, estimate through the cache, predicted error. The daemon's
//!   engine and the experiments both plan levels through it.
//! - [`drape`] — the shadow area and drape coefficient of a cloth over a
//!   support, a physical measure to compare levels by.
//! - [`turns`] — where long work (recordings, estimates) may give way to
//!   other work; the caller decides whether it does.
//! - [`hash`] — FNV-1a, the one hash of file names, checksums and digests.
//! - [`atomic`] — the one atomic file replacement (cache entries, snapshots).
//! - [`names`] — the one parser of integrator, method and mass names.
//! - [`problems`] — the one way input is validated and its problems worded.

#![warn(missing_docs)]

pub mod atomic;
pub mod cache;
pub mod drape;
pub mod estimate;
pub mod hash;
pub mod level;
pub mod lod;
pub mod mesh;
pub mod names;
pub mod plan;
mod ply;
pub mod points;
pub mod problems;
pub mod scene;
pub mod sim;
pub mod touch;
pub mod turns;
