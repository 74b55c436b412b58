//! Atomic file replacement, the one way lodcloth writes a file that a crash
//! must never leave torn (coefficient cache entries, instance snapshots).
//!
//! [`write()`] writes a temporary file unique to this write in the same
//! directory (`.<final name>.<pid>.<counter>.tmp`, created exclusively),
//! `fsync`s it, renames it over the final name (atomic on POSIX file systems)
//! and `fsync`s the directory. A reader sees the old file or the new one,
//! never a mix, even when the writer is killed or the machine loses power;
//! two writers of the same file (a periodic save and a shutdown save) never
//! share a temporary file, so the last rename wins whole. A crash leaves at
//! most a temporary file behind, which [`remove_stale_temp_files`] deletes.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime};

/// Temporary files end with this.
pub const TEMP_SUFFIX: &str = ".tmp";

/// A temporary file this old is abandoned even if its writer still runs (a
/// write takes milliseconds).
pub const STALE_TEMP_AGE: Duration = Duration::from_secs(60);

/// Numbers temporary files within this process (with the pid, unique per host).
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// A file-system operation of an atomic write or a sweep failed.
#[derive(Debug, thiserror::Error)]
#[error("{op} {path}: {source}")]
pub struct FileError {
    /// What was being done, e.g. "cannot rename into".
    pub op: &'static str,
    /// The file or directory it was done to.
    pub path: PathBuf,
    /// What the operating system said.
    pub source: io::Error,
}

fn file_err<'a>(op: &'static str, path: &'a Path) -> impl FnOnce(io::Error) -> FileError + 'a {
    move |source| FileError {
        op,
        path: path.to_path_buf(),
        source,
    }
}

/// Replace `dir/file_name` with `bytes` atomically (see the module docs).
/// `dir` must exist. Returns the final path.
pub fn write(dir: &Path, file_name: &str, bytes: &[u8]) -> Result<PathBuf, FileError> {
    let path = dir.join(file_name);
    let (tmp_path, mut file) = create_temp(dir, file_name)?;
    let written = file
        .write_all(bytes)
        .and_then(|()| file.sync_all())
        .map_err(file_err("cannot write", &tmp_path));
    drop(file);
    let renamed = written.and_then(|()| fs::rename(&tmp_path, &path).map_err(file_err("cannot rename into", &path)));
    if let Err(e) = renamed {
        // Best effort: the file is incomplete or orphaned either way, and a
        // later sweep would remove it.
        let _ = fs::remove_file(&tmp_path);
        return Err(e);
    }
    sync_dir(dir)?;
    Ok(path)
}

/// Creates `.<file_name>.<pid>.<counter>.tmp`, exclusively (a name left by
/// an earlier process with a reused pid is skipped, never reused).
fn create_temp(dir: &Path, file_name: &str) -> Result<(PathBuf, fs::File), FileError> {
    let pid = std::process::id();
    loop {
        let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!(".{file_name}.{pid}.{n}{TEMP_SUFFIX}"));
        match fs::OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(f) => return Ok((path, f)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(file_err("cannot create", &path)(e)),
        }
    }
}

/// Deletes the temporary files in `dir` that [`write()`] left for final names
/// ending in `final_suffix` and whose writer is gone: its process no longer
/// runs (checked on Linux via /proc) or the file is older than
/// [`STALE_TEMP_AGE`]. Returns how many were removed. Problems with single
/// files are logged and skipped; deleting a live writer's file by mistake only
/// makes that write fail, it never damages a final file.
pub fn remove_stale_temp_files(dir: &Path, final_suffix: &str) -> Result<usize, FileError> {
    let entries = fs::read_dir(dir).map_err(file_err("cannot list directory", dir))?;
    let now = SystemTime::now();
    let mut removed = 0;
    for entry in entries {
        let entry = match entry {
            Ok(e) => e,
            Err(e) => {
                tracing::warn!(dir = %dir.display(), error = %e, "cannot list a directory entry");
                continue;
            }
        };
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(pid) = temp_file_pid(name, final_suffix) else {
            continue;
        };
        let path = entry.path();
        let too_old = entry
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| now.duration_since(t).ok())
            .is_some_and(|age| age > STALE_TEMP_AGE);
        if !(too_old || process_is_gone(pid)) {
            continue;
        }
        match fs::remove_file(&path) {
            Ok(()) => removed += 1,
            // Another process cleaned it first.
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!(path = %path.display(), error = %e, "cannot remove a stale temporary file"),
        }
    }
    Ok(removed)
}

/// The writer's pid if `name` is one of [`write()`]'s temporary files for a
/// final name ending in `final_suffix` (`.<final name>.<pid>.<counter>.tmp`).
pub fn temp_file_pid(name: &str, final_suffix: &str) -> Option<u32> {
    let stem = name.strip_prefix('.')?.strip_suffix(TEMP_SUFFIX)?;
    let mut parts = stem.rsplitn(3, '.');
    let counter = parts.next()?;
    let pid = parts.next()?;
    let final_name = parts.next()?;
    if !final_name.ends_with(final_suffix) || counter.parse::<u64>().is_err() {
        return None;
    }
    pid.parse().ok()
}

/// True only when we know `pid` no longer runs: on Linux, no /proc/<pid>
/// (assumes the directory is not shared across pid namespaces; if it is, a
/// live writer's temporary file may go and its write fails, nothing worse).
/// Elsewhere always false, so only the age rule applies.
fn process_is_gone(pid: u32) -> bool {
    if pid == std::process::id() {
        return false;
    }
    if cfg!(target_os = "linux") && Path::new("/proc/self").exists() {
        !Path::new("/proc").join(pid.to_string()).exists()
    } else {
        false
    }
}

/// `fsync` of a directory, so a rename in it survives a power loss.
#[cfg(unix)]
fn sync_dir(dir: &Path) -> Result<(), FileError> {
    fs::File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(file_err("cannot sync directory", dir))
}

/// Windows cannot open directories as files; the rename itself is durable
/// enough here.
#[cfg(not(unix))]
fn sync_dir(_dir: &Path) -> Result<(), FileError> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temp_file_names_parse_back_to_their_pid() {
        assert_eq!(temp_file_pid(".a.toml.4242.7.tmp", ".toml"), Some(4242));
        assert_eq!(temp_file_pid("a.toml", ".toml"), None);
        assert_eq!(temp_file_pid(".x.toml.abc.1.tmp", ".toml"), None);
        assert_eq!(temp_file_pid(".notes.4242.7.tmp", ".toml"), None);
        assert_eq!(temp_file_pid(".a.snapshot.4242.7.tmp", ".snapshot"), Some(4242));
    }

    #[test]
    fn two_writes_of_one_file_never_share_a_temporary_file_and_leave_none() {
        let dir = tempfile::tempdir().expect("temp dir");
        let a = write(dir.path(), "x.snapshot", b"first").expect("write");
        write(dir.path(), "x.snapshot", b"second").expect("write");
        assert_eq!(fs::read(&a).expect("read"), b"second");
        let names: Vec<_> = fs::read_dir(dir.path())
            .expect("list")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("x.snapshot")]);
    }

    #[test]
    fn a_dead_writers_temporary_file_is_swept_and_a_live_ones_is_kept() {
        let dir = tempfile::tempdir().expect("temp dir");
        // pid 0 is never a process of ours (it is the scheduler), so /proc has no entry.
        let dead = dir.path().join(".x.snapshot.0.3.tmp");
        let live = dir
            .path()
            .join(format!(".x.snapshot.{}.999999.tmp", std::process::id()));
        let other = dir.path().join(".x.toml.0.3.tmp");
        for p in [&dead, &live, &other] {
            fs::write(p, b"partial").expect("write");
        }
        let removed = remove_stale_temp_files(dir.path(), ".snapshot").expect("sweep");
        if cfg!(target_os = "linux") {
            assert_eq!(removed, 1);
            assert!(!dead.exists());
        }
        assert!(live.exists() && other.exists());
    }
}
