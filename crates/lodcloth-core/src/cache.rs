//! On-disk cache of estimated material coefficients.
//!
//! Estimating coefficients for a coarse level can take minutes, so results are
//! kept in a directory, one TOML file per [`CacheKey`]: (scene, hash of the
//! scene text, reference resolution, target resolution, method, mass
//! convention, integrator, dt).
//!
//! # Crash safety
//! A file is never written in place: [`CoefficientCache::put`] replaces it
//! through [`crate::atomic::write`] (unique temporary file, `fsync`, rename,
//! `fsync` of the directory). A reader therefore sees the old file or the new
//! one, never a torn one, even if the writer is killed (`kill -9`) or the
//! machine loses power. A crash leaves at most a `*.tmp` file behind, which
//! [`CoefficientCache::open`] deletes.
//!
//! # Trust
//! Files can still be damaged by other means (disk errors, hand edits, copies),
//! so every read checks, in order: a trailing checksum over the whole body
//! (FNV-1a 64; any single changed byte is always detected, because each FNV-1a
//! step is a bijection of the state), the TOML schema, that the stored key is
//! the requested key (a digest collision or a renamed file must not hand back
//! another experiment's coefficients), and that every coefficient is finite
//! with K > 0 and C ≥ 0. Any failure is a [`CacheError::Corrupt`] naming the
//! file and the problem; [`CoefficientCache::get_or_compute`] then recomputes
//! and overwrites it.
//!
//! # File format (version 1)
//! ```toml
//! # lodcloth coefficient cache; a checksum guards this file: delete it to recompute, do not edit it.
//! format = 1
//! created_unix = 1767225600
//!
//! [key]
//! scene = "paper-1-top-edge"
//! scene_hash = "9f3c0d2a41b7e605"
//! reference = [64, 64]
//! target = [40, 40]
//! method = "fit"
//! mass = "lumped"
//! integrator = "rk4"
//! dt = 0.0002
//!
//! [material.structural]
//! k = 1234.5
//! c = 0.25
//! # … shear, bend …
//!
//! [notes]
//! training_error = 0.0031
//! # checksum = fnv1a64:0123456789abcdef
//! ```
//! The checksum covers every byte before its line. Floats are written in
//! Rust's shortest round-trip form, so every `f64` reads back bit for bit.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use crate::atomic::{self, FileError};
use crate::hash::{fnv1a64, Fnv1a64};
use crate::scene::MassConvention;
use crate::sim::{Integrator, Material, SpringClass, SpringCoeffs};

/// Version written to and required in the `format` field.
/// 2: coefficients per spring class (u and v directions apart); format-1
/// files, one value per kind, are refused and recomputed.
const FORMAT_VERSION: u32 = 2;

/// First line of every cache file.
const HEADER: &str =
    "# lodcloth coefficient cache; a checksum guards this file: delete it to recompute, do not edit it.\n";

/// Start of the last line of every cache file; 16 lower-case hex digits follow.
const CHECKSUM_PREFIX: &str = "# checksum = fnv1a64:";

/// Longest scene name (in bytes) kept in the readable part of a file name;
/// the digest, not the prefix, makes names unique.
const MAX_SCENE_IN_NAME: usize = 40;
/// Longest method, mass or integrator name kept in a file name.
const MAX_FIELD_IN_NAME: usize = 24;

// ---------------------------------------------------------------- key and entry

/// What a set of estimated coefficients depends on; one cache file per key.
///
/// Equality (and `Hash`) compare `dt` by its bits, so two keys are equal exactly when they
/// have the same digest input (0.0 and −0.0 differ; a NaN equals itself).
#[derive(Debug, Clone)]
pub struct CacheKey {
    /// Scene name (from the scene file's `name`).
    pub scene: String,
    /// [`fnv1a64`] of the scene file's text, so an edited scene misses the cache.
    pub scene_hash: u64,
    /// Reference (fine) resolution the coefficients were fitted against, (nx, ny).
    pub reference: (usize, usize),
    /// Target (coarse) resolution the coefficients are for, (nx, ny).
    pub target: (usize, usize),
    /// Estimation method name (e.g. "same", "fit").
    pub method: String,
    /// Mass convention name ([`MassConvention::name`]).
    pub mass: String,
    /// Integrator name ([`Integrator::name`]).
    pub integrator: String,
    /// Time step in seconds; compared and hashed by its exact bits.
    pub dt: f64,
}

impl PartialEq for CacheKey {
    fn eq(&self, other: &Self) -> bool {
        self.scene == other.scene
            && self.scene_hash == other.scene_hash
            && self.reference == other.reference
            && self.target == other.target
            && self.method == other.method
            && self.mass == other.mass
            && self.integrator == other.integrator
            && self.dt.to_bits() == other.dt.to_bits()
    }
}

impl Eq for CacheKey {}

/// Consistent with `PartialEq` (dt by its bits), so keys can index maps.
impl std::hash::Hash for CacheKey {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.scene.hash(state);
        self.scene_hash.hash(state);
        self.reference.hash(state);
        self.target.hash(state);
        self.method.hash(state);
        self.mass.hash(state);
        self.integrator.hash(state);
        self.dt.to_bits().hash(state);
    }
}

impl CacheKey {
    /// A key from typed parts; `scene_text` is the scene file's full text.
    pub fn new(
        scene: &str,
        scene_text: &str,
        reference: (usize, usize),
        target: (usize, usize),
        method: &str,
        mass: MassConvention,
        integrator: Integrator,
        dt: f64,
    ) -> CacheKey {
        CacheKey {
            scene: scene.to_string(),
            scene_hash: fnv1a64(scene_text.as_bytes()),
            reference,
            target,
            method: method.to_string(),
            mass: mass.name().to_string(),
            integrator: integrator.name().to_string(),
            dt,
        }
    }

    /// [`fnv1a64`] over every field, in declaration order: a version tag, then
    /// strings as (length as u64 LE, UTF-8 bytes), integers as u64 LE, `dt` as
    /// its IEEE-754 bits (u64 LE). Stable across platforms and Rust versions.
    pub fn digest(&self) -> u64 {
        let mut h = Fnv1a64::new();
        h.write_str("lodcloth-cache-key-v1");
        h.write_str(&self.scene);
        h.write_u64(self.scene_hash);
        h.write_u64(self.reference.0 as u64);
        h.write_u64(self.reference.1 as u64);
        h.write_u64(self.target.0 as u64);
        h.write_u64(self.target.1 as u64);
        h.write_str(&self.method);
        h.write_str(&self.mass);
        h.write_str(&self.integrator);
        h.write_u64(self.dt.to_bits());
        h.finish()
    }

    /// File name for this key: a readable prefix (sanitised, possibly
    /// truncated) and the 16-hex-digit [`CacheKey::digest`], e.g.
    /// `paper-1-top-edge_64x64_to_40x40_fit_lumped_rk4_dt2e-4_0123456789abcdef.toml`.
    pub fn file_name(&self) -> String {
        format!(
            "{}_{}x{}_to_{}x{}_{}_{}_{}_dt{}_{:016x}.toml",
            sanitize(&self.scene, MAX_SCENE_IN_NAME),
            self.reference.0,
            self.reference.1,
            self.target.0,
            self.target.1,
            sanitize(&self.method, MAX_FIELD_IN_NAME),
            sanitize(&self.mass, MAX_FIELD_IN_NAME),
            sanitize(&self.integrator, MAX_FIELD_IN_NAME),
            sanitize(&format!("{:e}", self.dt), MAX_FIELD_IN_NAME),
            self.digest()
        )
    }

    /// Names of the fields where `self` and `other` differ (for error messages).
    fn differences(&self, other: &CacheKey) -> Vec<String> {
        let mut d = Vec::new();
        let mut check = |name: &str, a: String, b: String| {
            if a != b {
                d.push(format!("{name} {a} (wanted {b})"));
            }
        };
        check("scene", format!("{:?}", self.scene), format!("{:?}", other.scene));
        check(
            "scene_hash",
            format!("{:016x}", self.scene_hash),
            format!("{:016x}", other.scene_hash),
        );
        check(
            "reference",
            format!("{:?}", self.reference),
            format!("{:?}", other.reference),
        );
        check("target", format!("{:?}", self.target), format!("{:?}", other.target));
        check("method", format!("{:?}", self.method), format!("{:?}", other.method));
        check("mass", format!("{:?}", self.mass), format!("{:?}", other.mass));
        check(
            "integrator",
            format!("{:?}", self.integrator),
            format!("{:?}", other.integrator),
        );
        check(
            "dt",
            format!("{:e} (bits {:016x})", self.dt, self.dt.to_bits()),
            format!("{:e} (bits {:016x})", other.dt, other.dt.to_bits()),
        );
        d
    }
}

/// Keeps ASCII letters, digits, '-' and '.'; anything else (including '_',
/// the field separator, and path separators) becomes '-'. At most `max` bytes.
fn sanitize(s: &str, max: usize) -> String {
    let mut out: String = s
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                c
            } else {
                '-'
            }
        })
        .take(max)
        .collect();
    if out.is_empty() || out.starts_with('.') {
        // Never a hidden or empty component (temporary files start with '.').
        out.insert(0, 'x');
    }
    out
}

/// One cached result: coefficients for a key, with bookkeeping.
#[derive(Debug, Clone, PartialEq)]
pub struct CacheEntry {
    /// The estimated coefficients: finite, K > 0, C ≥ 0.
    pub material: Material,
    /// What they were estimated for.
    pub key: CacheKey,
    /// When they were estimated, seconds since the Unix epoch.
    pub created_unix: u64,
    /// Finite numbers about the estimation (e.g. "training_error",
    /// "estimation_seconds"); sorted, so files are reproducible.
    pub notes: BTreeMap<String, f64>,
}

impl CacheEntry {
    /// An entry created now, with no notes.
    pub fn new(key: CacheKey, material: Material) -> CacheEntry {
        let created_unix = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
        CacheEntry {
            material,
            key,
            created_unix,
            notes: BTreeMap::new(),
        }
    }

    /// Every problem that would make this entry unusable, as readable phrases.
    fn problems(&self) -> Vec<String> {
        let mut p = Vec::new();
        for kind in SpringClass::ALL {
            let s = self.material.get(kind);
            // `!(x > 0.0)` also rejects NaN. K = 0 is a spring type the
            // model does not have (surfaces have no shear springs); it must
            // then have no damping either.
            let absent = s.k == 0.0 && s.c == 0.0;
            let usable = absent || (s.k.is_finite() && s.k > 0.0);
            if !usable {
                p.push(format!(
                    "{kind} stiffness k = {} is not finite and > 0 (nor 0 with c = 0, an absent type)",
                    s.k
                ));
            }
            if !(s.c.is_finite() && s.c >= 0.0) {
                p.push(format!("{kind} damping c = {} is not finite and ≥ 0", s.c));
            }
        }
        for (name, v) in &self.notes {
            if !v.is_finite() {
                p.push(format!("note {name:?} = {v} is not finite"));
            }
        }
        if !(self.key.dt.is_finite() && self.key.dt > 0.0) {
            p.push(format!("key dt = {} is not finite and > 0", self.key.dt));
        }
        if self.created_unix > i64::MAX as u64 {
            p.push(format!(
                "created_unix = {} does not fit a TOML integer",
                self.created_unix
            ));
        }
        p
    }
}

/// Where [`CoefficientCache::get_or_compute`]'s entry came from.
#[derive(Debug, Clone, PartialEq)]
pub enum Provenance {
    /// Read from a valid cache file.
    Hit,
    /// No cache file existed; computed and stored.
    Computed,
    /// The cache file was unusable (`reason` says why); computed and stored over it.
    RecomputedAfterCorrupt {
        /// Why the file could not be used.
        reason: String,
    },
}

/// Why the cache could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// A file-system operation failed (permissions, full disk, …).
    #[error("coefficient cache: {op} {path}: {source}")]
    Io {
        /// What was being done, e.g. "cannot read".
        op: &'static str,
        /// The file or directory it was done on.
        path: PathBuf,
        /// What the operating system reported.
        source: io::Error,
    },
    /// A cache file exists but cannot be trusted; recomputing replaces it.
    #[error("coefficient cache file {path} is corrupt: {reason}")]
    Corrupt {
        /// The cache file.
        path: PathBuf,
        /// What is wrong with it (checksum, format, key).
        reason: String,
    },
    /// An entry was refused before writing (it would be refused on reading),
    /// or a computed entry does not belong to the requested key.
    #[error("coefficient cache: refusing entry for {file_name}: {reason}")]
    Invalid {
        /// The entry's file name in the cache directory.
        file_name: String,
        /// Why it was refused.
        reason: String,
    },
}

impl From<FileError> for CacheError {
    fn from(e: FileError) -> CacheError {
        CacheError::Io {
            op: e.op,
            path: e.path,
            source: e.source,
        }
    }
}

fn io_err<'a>(op: &'static str, path: &'a Path) -> impl FnOnce(io::Error) -> CacheError + 'a {
    move |source| CacheError::Io {
        op,
        path: path.to_path_buf(),
        source,
    }
}

// ---------------------------------------------------------------- file format

/// The file as serde sees it (mirrors of the domain types, which carry no
/// serde derives so that `sim` stays free of I/O concerns).
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileRepr {
    format: u32,
    created_unix: u64,
    key: KeyRepr,
    material: MaterialRepr,
    #[serde(default)]
    notes: BTreeMap<String, f64>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyRepr {
    scene: String,
    /// Hex, because TOML integers are signed 64-bit.
    scene_hash: String,
    reference: (usize, usize),
    target: (usize, usize),
    method: String,
    mass: String,
    integrator: String,
    dt: f64,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialRepr {
    structural_u: CoeffsRepr,
    structural_v: CoeffsRepr,
    shear: CoeffsRepr,
    bend_u: CoeffsRepr,
    bend_v: CoeffsRepr,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CoeffsRepr {
    k: f64,
    c: f64,
}

impl From<SpringCoeffs> for CoeffsRepr {
    fn from(s: SpringCoeffs) -> Self {
        CoeffsRepr { k: s.k, c: s.c }
    }
}

impl From<CoeffsRepr> for SpringCoeffs {
    fn from(s: CoeffsRepr) -> Self {
        SpringCoeffs { k: s.k, c: s.c }
    }
}

/// Serialises a valid entry: header, TOML body, checksum line.
fn encode(entry: &CacheEntry) -> Result<String, String> {
    let k = &entry.key;
    let m = &entry.material;
    let repr = FileRepr {
        format: FORMAT_VERSION,
        created_unix: entry.created_unix,
        key: KeyRepr {
            scene: k.scene.clone(),
            scene_hash: format!("{:016x}", k.scene_hash),
            reference: k.reference,
            target: k.target,
            method: k.method.clone(),
            mass: k.mass.clone(),
            integrator: k.integrator.clone(),
            dt: k.dt,
        },
        material: MaterialRepr {
            structural_u: m.get(SpringClass::StructuralU).into(),
            structural_v: m.get(SpringClass::StructuralV).into(),
            shear: m.get(SpringClass::Shear).into(),
            bend_u: m.get(SpringClass::BendU).into(),
            bend_v: m.get(SpringClass::BendV).into(),
        },
        notes: entry.notes.clone(),
    };
    let toml = toml::to_string(&repr).map_err(|e| e.to_string())?;
    let mut text = String::with_capacity(HEADER.len() + toml.len() + 64);
    text.push_str(HEADER);
    text.push_str(&toml);
    if !text.ends_with('\n') {
        text.push('\n');
    }
    let sum = fnv1a64(text.as_bytes());
    // Writing to a String cannot fail.
    let _ = writeln!(text, "{CHECKSUM_PREFIX}{sum:016x}");
    Ok(text)
}

/// Checks and parses a file's bytes; `Err` is the reason it is corrupt.
fn decode(bytes: &[u8], wanted: &CacheKey) -> Result<CacheEntry, String> {
    if bytes.is_empty() {
        return Err("the file is empty".into());
    }
    let text = std::str::from_utf8(bytes).map_err(|e| format!("not UTF-8 text ({e})"))?;
    let body_and_line = text
        .strip_suffix('\n')
        .ok_or("the last line is incomplete (truncated file?)")?;
    let line_start = body_and_line.rfind('\n').map_or(0, |i| i + 1);
    let (body, last_line) = body_and_line.split_at(line_start);
    let stored = last_line
        .strip_prefix(CHECKSUM_PREFIX)
        .ok_or("the last line is not the checksum line (truncated file, or not a cache file)")?;
    if stored.len() != 16 || !stored.bytes().all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase()) {
        return Err(format!("malformed checksum {stored:?} (want 16 lower-case hex digits)"));
    }
    let actual = format!("{:016x}", fnv1a64(body.as_bytes()));
    if stored != actual {
        return Err(format!(
            "checksum mismatch: the file says {stored}, its content hashes to {actual} (torn or edited file)"
        ));
    }
    // The format first: a file from another version has other fields, and
    // saying so beats a parse error about the first field that differs.
    #[derive(Deserialize)]
    struct FormatOnly {
        format: u32,
    }
    if let Ok(FormatOnly { format }) = toml::from_str::<FormatOnly>(body) {
        if format != FORMAT_VERSION {
            return Err(format!(
                "written in cache format {format}, this build reads format {FORMAT_VERSION} \
                 (format 2: coefficients per spring class)"
            ));
        }
    }
    let repr: FileRepr =
        toml::from_str(body).map_err(|e| format!("invalid TOML: {}", e.to_string().trim_end().replace('\n', " ")))?;
    let k = repr.key;
    let scene_hash = (k.scene_hash.len() == 16)
        .then(|| u64::from_str_radix(&k.scene_hash, 16).ok())
        .flatten()
        .ok_or_else(|| format!("key.scene_hash {:?} is not 16 hex digits", k.scene_hash))?;
    let key = CacheKey {
        scene: k.scene,
        scene_hash,
        reference: k.reference,
        target: k.target,
        method: k.method,
        mass: k.mass,
        integrator: k.integrator,
        dt: k.dt,
    };
    if key != *wanted {
        return Err(format!(
            "it holds coefficients for another key: {} (renamed or copied file, or a digest collision)",
            key.differences(wanted).join(", ")
        ));
    }
    let m = repr.material;
    let entry = CacheEntry {
        material: Material {
            springs: [
                m.structural_u.into(),
                m.structural_v.into(),
                m.shear.into(),
                m.bend_u.into(),
                m.bend_v.into(),
            ],
        },
        key,
        created_unix: repr.created_unix,
        notes: repr.notes,
    };
    let problems = entry.problems();
    if !problems.is_empty() {
        return Err(problems.join("; "));
    }
    Ok(entry)
}

// ---------------------------------------------------------------- the cache

/// A directory of cache files, safe to share between threads and processes
/// (readers never see partial writes; concurrent writers of one key each
/// leave a complete file, the last rename wins).
#[derive(Debug, Clone)]
pub struct CoefficientCache {
    dir: PathBuf,
}

impl CoefficientCache {
    /// Opens (creating if needed) the cache directory and deletes temporary
    /// files that crashed writers left behind.
    pub fn open(dir: impl Into<PathBuf>) -> Result<CoefficientCache, CacheError> {
        let dir = dir.into();
        fs::create_dir_all(&dir).map_err(io_err("cannot create directory", &dir))?;
        let cache = CoefficientCache { dir };
        cache.remove_stale_temp_files()?;
        Ok(cache)
    }

    /// The cache directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where the file for `key` lives (whether or not it exists).
    pub fn path_for(&self, key: &CacheKey) -> PathBuf {
        self.dir.join(key.file_name())
    }

    /// The entry for `key`: `Ok(None)` if there is no file, `Err(Corrupt)` if
    /// the file is damaged, belongs to another key or holds invalid values.
    pub fn get(&self, key: &CacheKey) -> Result<Option<CacheEntry>, CacheError> {
        let path = self.path_for(key);
        let bytes = match fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(io_err("cannot read", &path)(e)),
        };
        decode(&bytes, key)
            .map(Some)
            .map_err(|reason| CacheError::Corrupt { path, reason })
    }

    /// Stores `entry` under its key, atomically: temp file, `fsync`, rename
    /// over the final name, `fsync` of the directory. Returns the final path.
    /// Refuses entries that [`CoefficientCache::get`] would reject.
    pub fn put(&self, entry: &CacheEntry) -> Result<PathBuf, CacheError> {
        let file_name = entry.key.file_name();
        let problems = entry.problems();
        if !problems.is_empty() {
            return Err(CacheError::Invalid {
                file_name,
                reason: problems.join("; "),
            });
        }
        let text = encode(entry).map_err(|reason| CacheError::Invalid {
            file_name: file_name.clone(),
            reason,
        })?;
        atomic::write(&self.dir, &file_name, text.as_bytes()).map_err(CacheError::from)
    }

    /// The cached entry for `key`, or `compute()`'s result, stored first.
    ///
    /// A corrupt file is logged (`tracing::warn!`), reported in the
    /// [`Provenance`], and replaced. I/O errors (e.g. an unreadable
    /// directory) and a failure to store the computed entry are returned as
    /// errors. `compute` must return an entry for exactly `key`.
    pub fn get_or_compute<E>(
        &self,
        key: &CacheKey,
        compute: impl FnOnce() -> Result<CacheEntry, E>,
    ) -> Result<(CacheEntry, Provenance), E>
    where
        E: From<CacheError>,
    {
        let provenance = match self.get(key) {
            Ok(Some(entry)) => return Ok((entry, Provenance::Hit)),
            Ok(None) => Provenance::Computed,
            Err(CacheError::Corrupt { path, reason }) => {
                tracing::warn!(path = %path.display(), %reason, "corrupt coefficient cache file; recomputing");
                Provenance::RecomputedAfterCorrupt { reason }
            }
            Err(e) => return Err(e.into()),
        };
        let entry = compute()?;
        if entry.key != *key {
            return Err(CacheError::Invalid {
                file_name: key.file_name(),
                reason: format!(
                    "the computed entry is for another key: {}",
                    entry.key.differences(key).join(", ")
                ),
            }
            .into());
        }
        self.put(&entry)?;
        Ok((entry, provenance))
    }

    /// Deletes temporary files left by crashed writers: those whose writer
    /// process is gone (checked on Linux via /proc) and any older than a
    /// minute. Returns how many were removed. Problems with single files are
    /// logged and skipped; deleting a live writer's file by mistake only makes
    /// that writer's `put` fail, it never damages a cache file.
    pub fn remove_stale_temp_files(&self) -> Result<usize, CacheError> {
        Ok(atomic::remove_stale_temp_files(&self.dir, ".toml")?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper_key() -> CacheKey {
        CacheKey {
            scene: "paper-1-top-edge".into(),
            scene_hash: 0x0123_4567_89ab_cdef,
            reference: (64, 64),
            target: (40, 40),
            method: "fit".into(),
            mass: "lumped".into(),
            integrator: "rk4".into(),
            dt: 2e-4,
        }
    }

    /// The digest input spelled out byte by byte, independently of `Fnv1a64`'s
    /// helpers: if this test fails, every existing cache file is orphaned.
    #[test]
    fn key_digest_is_fnv1a_over_length_prefixed_fields_and_never_changes() {
        let k = paper_key();
        let mut bytes = Vec::new();
        let mut s = |x: &str| {
            bytes.extend((x.len() as u64).to_le_bytes());
            bytes.extend(x.as_bytes());
        };
        s("lodcloth-cache-key-v1");
        s("paper-1-top-edge");
        let mut nums = Vec::new();
        for n in [0x0123_4567_89ab_cdef_u64, 64, 64, 40, 40] {
            nums.extend(n.to_le_bytes());
        }
        bytes.extend(nums);
        for x in ["fit", "lumped", "rk4"] {
            bytes.extend((x.len() as u64).to_le_bytes());
            bytes.extend(x.as_bytes());
        }
        bytes.extend(0x3F2A_36E2_EB1C_432D_u64.to_le_bytes()); // 2e-4
        assert_eq!(2e-4_f64.to_bits(), 0x3F2A_36E2_EB1C_432D);
        assert_eq!(k.digest(), fnv1a64(&bytes));
        // Pinned value (also computed with a separate Python FNV-1a).
        assert_eq!(format!("{:016x}", k.digest()), PINNED_DIGEST);
        assert_eq!(
            k.file_name(),
            format!("paper-1-top-edge_64x64_to_40x40_fit_lumped_rk4_dt2e-4_{PINNED_DIGEST}.toml")
        );
    }

    const PINNED_DIGEST: &str = "a2947356b07c0039";

    #[test]
    fn file_names_are_safe_path_components() {
        let mut k = paper_key();
        k.scene = "../../etc/passwd".into();
        k.method = String::new();
        k.integrator = "a_b c/d".into();
        let name = k.file_name();
        assert!(!name.contains('/') && !name.starts_with('.'), "{name}");
        assert!(
            name.starts_with("x..-..-etc-passwd_64x64_to_40x40_x_lumped_a-b-c-d_dt2e-4_"),
            "{name}"
        );
        k.scene = "é".repeat(100);
        assert!(k.file_name().len() < 200);
    }

    #[test]
    fn temp_file_names_parse_back_to_their_pid() {
        let name = format!(".{}.4242.7.tmp", paper_key().file_name());
        assert_eq!(atomic::temp_file_pid(&name, ".toml"), Some(4242));
        assert_eq!(atomic::temp_file_pid("paper.toml", ".toml"), None);
        assert_eq!(atomic::temp_file_pid(".x.toml.abc.1.tmp", ".toml"), None);
        assert_eq!(atomic::temp_file_pid(".notes.4242.7.tmp", ".toml"), None);
    }
}
