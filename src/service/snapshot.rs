//! Instance snapshots: what an instance needs to resume where it was after
//! the daemon restarts (level, method, coefficient version, frame, episode,
//! paused, the coefficients and dt it ran with, and the full state in f64),
//! one file per instance.
//!
//! The format is binary and self-checking:
//!
//! | bytes | what |
//! |---|---|
//! | 20 | `LODCLOTH SNAPSHOT 1\n` |
//! | 4 | header length `h` (u32, little-endian) |
//! | h | header: JSON ([`Header`]) |
//! | 8·3n | positions, SoA (x of every node, then y, then z), f64 LE |
//! | 8·3n | velocities, the same layout |
//! | 8 | FNV-1a 64 of every byte before it (u64 LE) |
//!
//! Files are written like the coefficient cache's: a temporary file,
//! `fsync`, rename over the final name, `fsync` of the directory; so a
//! `kill -9` leaves the old snapshot or the new one, and a damaged file fails
//! its checksum. [`encode`] and [`decode`] are pure; [`write`] and [`read`]
//! do the I/O.

use std::fs;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::atomic;
use crate::engine::{Coefficients, Snapshot};
use crate::estimate::Method;
use crate::hash::fnv1a64;
use crate::names;
use crate::plan::Level;
use crate::plan::{InstanceKind, InstancePlan};
use crate::sim::{Material, SpringCoeffs, State};

const MAGIC: &[u8; 20] = b"LODCLOTH SNAPSHOT 1\n";
/// Largest header accepted (it is a few hundred bytes).
const MAX_HEADER: usize = 64 * 1024;

/// Why a snapshot file was not used.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    #[error("cannot read {path}: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("cannot write {path}: {source}")]
    Write { path: String, source: std::io::Error },
    #[error("{path}: not a usable snapshot: {reason}")]
    Corrupt { path: String, reason: String },
}

/// The JSON header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Header {
    pub instance: String,
    /// [`identity`] of the instance's configuration, hex.
    pub identity: String,
    pub level: Level,
    pub method: String,
    pub coefficient_version: u32,
    pub frame: u64,
    pub episode: u64,
    pub paused: bool,
    pub time: f64,
    pub step: u64,
    pub nodes: usize,
    /// When it was taken (Unix milliseconds).
    pub saved_unix_ms: u64,
    /// The coefficients it ran with: (K, C) per spring class, structural u,
    /// structural v, shear, bend u, bend v (absent in files written before
    /// they were saved; three pairs, structural, shear, bend, in files
    /// written before u and v were told apart).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<Vec<[f64; 2]>>,
    /// The time step it ran with (s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dt: Option<f64>,
}

/// A snapshot read back: whose it is and the engine's part.
#[derive(Debug, Clone)]
pub struct Saved {
    pub instance: String,
    pub identity: u64,
    pub saved_unix_ms: u64,
    pub snapshot: Snapshot,
}

/// What a snapshot must match to be resumed: the instance's name, kind,
/// scene (its source text, and the point cloud's), reference, integrator
/// and configured dt. A config that changes any of these starts afresh.
pub fn identity(config: &InstancePlan) -> u64 {
    let source = match &config.kind {
        InstanceKind::Cloth(scene) => scene.source_hash,
        InstanceKind::Surface(scene) => scene.source_hash,
    };
    let text = format!(
        "{}\n{}\n{}\n{:016x}\n{}\n{}\n{}",
        config.name,
        config.kind_name(),
        config.scene_name(),
        source,
        config.reference(),
        config.integrator.name(),
        config
            .dt
            .map_or("auto".to_string(), |dt| format!("{:016x}", dt.to_bits())),
    );
    fnv1a64(text.as_bytes())
}

/// The file of `instance` in `dir`.
pub fn path(dir: &Path, instance: &str) -> PathBuf {
    dir.join(format!("{instance}.{SUFFIX}"))
}

/// A snapshot file's extension.
const SUFFIX: &str = "snapshot";

/// Deletes the temporary files of snapshot writes that a crash left in `dir`
/// (see [`atomic::remove_stale_temp_files`]); a missing `dir` has none.
pub fn sweep(dir: &Path) -> Result<usize, SnapshotError> {
    if !dir.is_dir() {
        return Ok(0);
    }
    atomic::remove_stale_temp_files(dir, SUFFIX).map_err(|e| SnapshotError::Write {
        path: e.path.display().to_string(),
        source: e.source,
    })
}

/// The bytes of a snapshot of `instance` (pure).
pub fn encode(instance: &str, identity: u64, saved_unix_ms: u64, s: &Snapshot) -> Vec<u8> {
    let n = s.state.n_nodes();
    let header = Header {
        instance: instance.to_string(),
        identity: format!("{identity:016x}"),
        level: s.level,
        method: s.method.name().to_string(),
        coefficient_version: s.coefficient_version,
        frame: s.frame,
        episode: s.episode,
        paused: s.paused,
        time: s.state.time,
        step: s.state.step,
        nodes: n,
        saved_unix_ms,
        material: s
            .coefficients
            .map(|c| c.material.springs.iter().map(|k| [k.k, k.c]).collect()),
        dt: s.coefficients.map(|c| c.dt),
    };
    let json = serde_json::to_vec(&header).unwrap_or_default();
    let mut out = Vec::with_capacity(MAGIC.len() + 4 + json.len() + 16 * 3 * n + 8);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&json);
    for x in s.state.pos.iter().chain(&s.state.vel) {
        out.extend_from_slice(&x.to_le_bytes());
    }
    let sum = fnv1a64(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// A snapshot from its bytes (pure); the error says what is wrong.
pub fn decode(bytes: &[u8]) -> Result<Saved, String> {
    let body_len = bytes
        .len()
        .checked_sub(8)
        .ok_or_else(|| format!("{} bytes: too short for a snapshot", bytes.len()))?;
    if bytes.len() < MAGIC.len() + 4 + 8 || bytes[..MAGIC.len()] != MAGIC[..] {
        return Err("it does not start with the snapshot signature (`LODCLOTH SNAPSHOT 1`)".into());
    }
    let (body, tail) = bytes.split_at(body_len);
    let stored = u64::from_le_bytes(tail.try_into().map_err(|_| "no checksum")?);
    let computed = fnv1a64(body);
    if stored != computed {
        return Err(format!(
            "checksum mismatch (stored {stored:016x}, computed {computed:016x}): truncated or damaged"
        ));
    }
    let rest = &body[MAGIC.len()..];
    let h = u32::from_le_bytes(rest[..4].try_into().map_err(|_| "no header length")?) as usize;
    if h > MAX_HEADER || 4 + h > rest.len() {
        return Err(format!("header length {h} does not fit the file"));
    }
    let header: Header = serde_json::from_slice(&rest[4..4 + h]).map_err(|e| format!("header: {e}"))?;
    let identity = u64::from_str_radix(&header.identity, 16)
        .map_err(|_| format!("header: identity `{}` is not hexadecimal", header.identity))?;
    let method = names::parse::<Method>(&header.method).map_err(|e| format!("header.method: {e}"))?;
    let values = &rest[4 + h..];
    let n = header.nodes;
    if n == 0 || values.len() != 16 * 3 * n {
        return Err(format!(
            "{} bytes of positions and velocities for {n} nodes (expected {})",
            values.len(),
            16 * 3 * n
        ));
    }
    let floats: Vec<f64> = values
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
        .collect();
    if let Some(i) = floats.iter().position(|x| !x.is_finite()) {
        let what = if i < 3 * n { "position" } else { "velocity" };
        return Err(format!("a non-finite {what} (value {i})"));
    }
    if !header.time.is_finite() || header.time < 0.0 {
        return Err(format!(
            "header: time {} is not a finite non-negative number",
            header.time
        ));
    }
    let coefficients = match (header.material, header.dt) {
        (None, None) => None,
        (Some(m), Some(dt)) => {
            if !(dt.is_finite() && dt > 0.0) {
                return Err(format!("header: dt {dt} is not a positive number"));
            }
            if let Some(bad) = m.iter().flatten().find(|x| !(x.is_finite() && **x >= 0.0)) {
                return Err(format!(
                    "header: material coefficient {bad} is not a finite non-negative number"
                ));
            }
            let pairs: Vec<SpringCoeffs> = m.iter().map(|&[k, c]| SpringCoeffs { k, c }).collect();
            let material = match pairs[..] {
                [s, h, b] => Material::isotropic([s, h, b]),
                [su, sv, h, bu, bv] => Material {
                    springs: [su, sv, h, bu, bv],
                },
                _ => {
                    return Err(format!(
                        "header: material has {} coefficient pairs, expected 5 (or 3 in older files)",
                        pairs.len()
                    ))
                }
            };
            Some(Coefficients { material, dt })
        }
        _ => return Err("header: material and dt come together".into()),
    };
    let (pos, vel) = floats.split_at(3 * n);
    Ok(Saved {
        instance: header.instance,
        identity,
        saved_unix_ms: header.saved_unix_ms,
        snapshot: Snapshot {
            level: header.level,
            method,
            coefficient_version: header.coefficient_version,
            frame: header.frame,
            episode: header.episode,
            paused: header.paused,
            state: State {
                pos: pos.to_vec(),
                vel: vel.to_vec(),
                time: header.time,
                step: header.step,
            },
            coefficients,
        },
    })
}

/// Write `bytes` as `instance`'s snapshot in `dir`, atomically (temporary
/// file, `fsync`, rename, `fsync` of the directory). Creates `dir`.
pub fn write(dir: &Path, instance: &str, bytes: &[u8]) -> Result<PathBuf, SnapshotError> {
    let final_path = path(dir, instance);
    let err = |p: &Path| {
        let path = p.display().to_string();
        move |source| SnapshotError::Write { path, source }
    };
    fs::create_dir_all(dir).map_err(err(dir))?;
    let file_name = format!("{instance}.{SUFFIX}");
    atomic::write(dir, &file_name, bytes).map_err(|e| SnapshotError::Write {
        path: e.path.display().to_string(),
        source: e.source,
    })?;
    Ok(final_path)
}

/// `instance`'s snapshot in `dir`: `Ok(None)` when there is none.
pub fn read(dir: &Path, instance: &str) -> Result<Option<Saved>, SnapshotError> {
    let p = path(dir, instance);
    let bytes = match fs::read(&p) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => {
            return Err(SnapshotError::Read {
                path: p.display().to_string(),
                source,
            })
        }
    };
    let corrupt = |reason: String| SnapshotError::Corrupt {
        path: p.display().to_string(),
        reason,
    };
    let saved = decode(&bytes).map_err(corrupt)?;
    if saved.instance != instance {
        return Err(corrupt(format!(
            "it is instance `{}`'s (a renamed or copied file)",
            saved.instance
        )));
    }
    Ok(Some(saved))
}

/// Whether `saved` can resume the instance `config` describes; the reason
/// when not.
pub fn fits(saved: &Saved, config: &InstancePlan) -> Result<(), String> {
    if saved.identity != identity(config) {
        return Err("the instance's scene, reference, integrator or dt changed since it was saved".into());
    }
    let level = saved.snapshot.level;
    if !config.levels.contains(&level) {
        return Err(format!("its level {level} is no longer among the instance's levels"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Snapshot {
        let n = 5;
        Snapshot {
            level: Level::new(4, 3),
            method: Method::Fit,
            coefficient_version: 7,
            frame: 12_345,
            episode: 2,
            paused: true,
            state: State {
                pos: (0..3 * n).map(|i| 0.1 * i as f64 - 0.3).collect(),
                vel: (0..3 * n).map(|i| (i as f64).sin() * 1e-3).collect(),
                time: 4.125,
                step: 4125,
            },
            coefficients: Some(Coefficients {
                material: Material {
                    springs: [
                        SpringCoeffs { k: 1234.5678, c: 0.1 },
                        SpringCoeffs { k: 987.25, c: 0.125 },
                        SpringCoeffs { k: 1.0 / 3.0, c: 0.0 },
                        SpringCoeffs { k: 7e-3, c: 2.5e-4 },
                        SpringCoeffs { k: 6e-3, c: 2e-4 },
                    ],
                },
                dt: 1.0 / 1200.0,
            }),
        }
    }

    /// Coefficients a fit produced (the daemon smoke test's paper-1 at
    /// 16×16) that serde_json's default float parser read back one ulp off,
    /// so a resumed level never re-attached its prediction.
    #[test]
    fn a_fits_coefficients_read_back_bit_for_bit() {
        let mut s = sample();
        let material = Material {
            springs: [
                SpringCoeffs {
                    k: 410.94006003970014,
                    c: 0.042396524507370484,
                },
                SpringCoeffs {
                    k: 412.90646105173084,
                    c: 0.042396524507370484,
                },
                SpringCoeffs {
                    k: 60.33903523924886,
                    c: 0.005710287456269357,
                },
                SpringCoeffs {
                    k: 8.034992096202258,
                    c: 0.0007642313924615084,
                },
                SpringCoeffs {
                    k: 8.003923469337847,
                    c: 0.0007642313924615084,
                },
            ],
        };
        s.coefficients = Some(Coefficients { material, dt: 0.001 });
        let back = decode(&encode("paper-1", 1, 0, &s)).expect("decodes").snapshot;
        assert_eq!(back.coefficients.map(|c| c.material), Some(material));
    }

    #[test]
    fn a_snapshot_reads_back_bit_for_bit() {
        let s = sample();
        let bytes = encode("paper-1", 0xfeed_beef, 42, &s);
        let back = decode(&bytes).expect("decodes");
        assert_eq!(back.instance, "paper-1");
        assert_eq!(back.identity, 0xfeed_beef);
        assert_eq!(back.saved_unix_ms, 42);
        let b = back.snapshot;
        assert_eq!((b.level, b.method, b.coefficient_version), (s.level, s.method, 7));
        assert_eq!((b.frame, b.episode, b.paused), (12_345, 2, true));
        assert_eq!(b.state.time.to_bits(), s.state.time.to_bits());
        assert_eq!(b.state.step, s.state.step);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&b.state.pos), bits(&s.state.pos));
        assert_eq!(bits(&b.state.vel), bits(&s.state.vel));
        // Exactly: a resumed instance re-attaches its prepared level only
        // if the material is the very one it ran with.
        assert_eq!(b.coefficients, s.coefficients);
    }

    #[test]
    fn a_snapshot_without_coefficients_reads_back_without_them() {
        let s = Snapshot {
            coefficients: None,
            ..sample()
        };
        let bytes = encode("a", 1, 2, &s);
        let text = String::from_utf8_lossy(&bytes);
        assert!(!text.contains("\"material\"") && !text.contains("\"dt\""));
        assert_eq!(decode(&bytes).expect("decodes").snapshot.coefficients, None);
    }

    #[test]
    fn impossible_coefficients_are_refused_by_name() {
        for (material, dt, needle) in [
            ("[[-1.0,0.0],[1.0,0.0],[1.0,0.0]]", "0.001", "material coefficient -1"),
            ("[[1.0,0.0],[1.0,0.0],[1.0,0.0]]", "0.0", "dt 0"),
        ] {
            let header = format!(
                "{{\"instance\":\"a\",\"identity\":\"1\",\"level\":\"1x1\",\"method\":\"same\",\
                 \"coefficient_version\":1,\"frame\":0,\"episode\":0,\"paused\":false,\"time\":0.0,\
                 \"step\":0,\"nodes\":1,\"saved_unix_ms\":0,\"material\":{material},\"dt\":{dt}}}"
            );
            let mut bytes = MAGIC.to_vec();
            bytes.extend_from_slice(&(header.len() as u32).to_le_bytes());
            bytes.extend_from_slice(header.as_bytes());
            bytes.extend_from_slice(&[0; 48]);
            let sum = fnv1a64(&bytes);
            bytes.extend_from_slice(&sum.to_le_bytes());
            let e = decode(&bytes).unwrap_err();
            assert!(e.contains(needle), "{needle}: {e}");
        }
    }

    #[test]
    fn every_damaged_byte_and_every_truncation_is_refused() {
        let bytes = encode("a", 1, 2, &sample());
        for i in 0..bytes.len() {
            let mut d = bytes.clone();
            d[i] ^= 0x20;
            assert!(decode(&d).is_err(), "byte {i} flipped was accepted");
        }
        for len in 0..bytes.len() {
            assert!(decode(&bytes[..len]).is_err(), "truncated to {len} was accepted");
        }
        let mut d = bytes.clone();
        d[30] ^= 1;
        let e = decode(&d).unwrap_err();
        assert!(e.contains("checksum"), "{e}");
        let e = decode(b"{\"not\": \"a snapshot\"}\n........").unwrap_err();
        assert!(e.contains("signature"), "{e}");
    }

    #[test]
    fn write_replaces_and_read_names_the_file_it_refuses() {
        let dir = std::env::temp_dir().join(format!("lodcloth-snapshot-unit-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        assert!(read(&dir, "a").expect("no dir is no snapshot").is_none());
        let mut s = sample();
        write(&dir, "a", &encode("a", 9, 0, &s)).expect("write");
        s.frame += 1;
        let p = write(&dir, "a", &encode("a", 9, 0, &s)).expect("overwrite");
        assert_eq!(read(&dir, "a").expect("read").expect("present").snapshot.frame, s.frame);
        // No temporary file is left behind.
        let names: Vec<String> = fs::read_dir(&dir)
            .expect("list")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec!["a.snapshot".to_string()]);
        // Another instance's file under this name.
        fs::copy(&p, path(&dir, "b")).expect("copy");
        let e = read(&dir, "b").unwrap_err().to_string();
        assert!(e.contains("b.snapshot") && e.contains("instance `a`"), "{e}");
        // Damaged.
        let mut bytes = fs::read(&p).expect("bytes");
        let last = bytes.len() - 20;
        bytes[last] ^= 0xff;
        fs::write(&p, bytes).expect("damage");
        let e = read(&dir, "a").unwrap_err().to_string();
        assert!(e.contains("a.snapshot") && e.contains("checksum"), "{e}");
        let _ = fs::remove_dir_all(&dir);
    }
}
