//! The coefficient cache: entries read back bit for bit; keys that differ in
//! any field never share a file; every kind of damaged file is refused with a
//! message naming it and is then recomputed; and a writer killed with SIGKILL
//! at any moment leaves the old file or the new one, never a torn one.

use crate::common;

use std::fs;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use common::{material, Rng};
use lodcloth::cache::{CacheEntry, CacheError, CacheKey, CoefficientCache, Provenance};
use lodcloth::hash::fnv1a64;
use lodcloth::scene::MassConvention;
use lodcloth::sim::{Integrator, Material};

// ---------------------------------------------------------------- helpers

fn key() -> CacheKey {
    CacheKey::new(
        "paper-1-top-edge",
        "name = \"paper-1-top-edge\"\n# scene text\n",
        (64, 64),
        (40, 40),
        "fit",
        MassConvention::Lumped,
        Integrator::Rk4,
        2e-4,
    )
}

fn entry_for(key: CacheKey, scale: f64) -> CacheEntry {
    let mut e = CacheEntry::new(
        key,
        material((1000.0 * scale, 0.5), (300.0 * scale, 0.25), (10.0 * scale, 0.0)),
    );
    e.created_unix = 1_767_225_600;
    e.notes.insert("training_error".into(), 0.0031 * scale);
    e.notes.insert("estimation_seconds".into(), 42.5);
    e
}

fn open(dir: &Path) -> CoefficientCache {
    CoefficientCache::open(dir).unwrap_or_else(|e| panic!("open {}: {e}", dir.display()))
}

fn bits(m: &Material) -> Vec<u64> {
    m.springs.iter().flat_map(|s| [s.k.to_bits(), s.c.to_bits()]).collect()
}

/// Equal down to the bits of every float (`==` would accept 0.0 for −0.0).
fn assert_identical(got: &CacheEntry, want: &CacheEntry) {
    assert_eq!(got.key, want.key, "key");
    assert_eq!(got.key.dt.to_bits(), want.key.dt.to_bits(), "dt bits");
    assert_eq!(bits(&got.material), bits(&want.material), "coefficient bits");
    assert_eq!(got.created_unix, want.created_unix);
    let note_bits = |e: &CacheEntry| {
        e.notes
            .iter()
            .map(|(k, v)| (k.clone(), v.to_bits()))
            .collect::<Vec<_>>()
    };
    assert_eq!(note_bits(got), note_bits(want), "note bits");
}

/// Error type for `get_or_compute` in these tests.
#[derive(Debug)]
enum TestError {
    Cache(CacheError),
    Compute(&'static str),
}

impl From<CacheError> for TestError {
    fn from(e: CacheError) -> Self {
        TestError::Cache(e)
    }
}

/// Files in `dir` (names), sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("list {}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

// ---------------------------------------------------------------- round trip

#[test]
fn put_then_get_returns_the_entry_bit_for_bit_including_awkward_floats() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = open(dir.path());
    assert!(cache.get(&key()).expect("get").is_none(), "empty cache must miss");

    let mut e = entry_for(key(), 1.0);
    e.material = material((1.0 / 3.0, 5e-324), (1e300, f64::MIN_POSITIVE), (f64::MAX, 0.1 + 0.2));
    e.key.dt = 1.0 / 3.0 * 1e-3;
    e.notes.insert("negative zero".into(), -0.0);
    e.notes.insert("quote \" and = and # and ünïcode".into(), -1.5e-310);
    let mut rng = Rng::new(7);
    for i in 0..500 {
        // Random bit patterns cover every exponent, subnormals included.
        let x = f64::from_bits(rng.next_u64());
        if x.is_finite() {
            e.notes.insert(format!("random {i:03}"), x);
        }
    }
    let path = cache.put(&e).expect("put");
    assert_eq!(path, cache.path_for(&e.key));
    assert_eq!(
        path.file_name().and_then(|n| n.to_str()),
        Some(e.key.file_name().as_str())
    );
    let got = cache.get(&e.key).expect("get").expect("hit after put");
    assert_identical(&got, &e);

    // A second put replaces the first.
    let e2 = entry_for(e.key.clone(), 2.0);
    cache.put(&e2).expect("put again");
    assert_identical(&cache.get(&e.key).expect("get").expect("hit"), &e2);
    assert_eq!(
        listing(dir.path()),
        vec![e.key.file_name()],
        "no temp files left behind"
    );
}

#[test]
fn the_file_is_readable_toml_with_a_trailing_checksum_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = open(dir.path());
    let path = cache.put(&entry_for(key(), 1.0)).expect("put");
    let text = fs::read_to_string(&path).expect("read");
    assert!(text.starts_with("# lodcloth coefficient cache"), "{text}");
    for needle in [
        "format = 2",
        "[key]",
        "scene = \"paper-1-top-edge\"",
        "dt = 0.0002",
        "[material.structural_u]",
        "k = 1000.0",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in\n{text}");
    }
    let (body, last) = text.trim_end_matches('\n').rsplit_once('\n').expect("several lines");
    let sum = last.strip_prefix("# checksum = fnv1a64:").expect("checksum line last");
    assert_eq!(sum, format!("{:016x}", fnv1a64(format!("{body}\n").as_bytes())));
}

#[test]
fn keys_differing_in_any_one_field_use_different_files_and_never_collide() {
    let base = key();
    let mut variants = vec![base.clone()];
    let mut vary = |f: &dyn Fn(&mut CacheKey)| {
        let mut k = base.clone();
        f(&mut k);
        variants.push(k);
    };
    // dt one ulp apart: `2.0000000000000001e-4` would parse to the same f64.
    vary(&|k| k.dt = f64::from_bits(2e-4_f64.to_bits() + 1));
    vary(&|k| k.dt = 1e-4);
    vary(&|k| k.method = "same".into());
    vary(&|k| k.mass = MassConvention::PerNode.name().into());
    vary(&|k| k.integrator = Integrator::ImplicitEuler.name().into());
    vary(&|k| k.scene_hash ^= 1);
    vary(&|k| k.scene = "paper-2".into());
    vary(&|k| k.reference = (64, 40));
    vary(&|k| k.target = (40, 64));
    vary(&|k| k.target = (20, 20));
    // Same readable prefix after sanitising ('_' and ' ' both become '-'): only the digest separates them.
    vary(&|k| k.method = "fit_a".into());
    vary(&|k| k.method = "fit a".into());

    let names: Vec<String> = variants.iter().map(CacheKey::file_name).collect();
    let mut unique = names.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), names.len(), "file names collide: {names:#?}");

    let dir = tempfile::tempdir().expect("temp dir");
    let cache = open(dir.path());
    for (i, k) in variants.iter().enumerate() {
        cache.put(&entry_for(k.clone(), 1.0 + i as f64)).expect("put");
    }
    for (i, k) in variants.iter().enumerate() {
        let got = cache.get(k).expect("get").expect("hit");
        assert_identical(&got, &entry_for(k.clone(), 1.0 + i as f64));
    }
}

// ---------------------------------------------------------------- corrupt files

/// Writes a valid file for `key()`, damages it with `damage`, then checks that
/// `get` refuses it with a `Corrupt` error naming the file and containing
/// `reason_part`, that `get_or_compute` recomputes and says why, and that the
/// recomputed entry is what `get` returns afterwards.
fn check_corruption_is_detected_and_repaired(
    case: &str,
    reason_part: &str,
    damage: impl FnOnce(&Path, &CoefficientCache),
) {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = open(dir.path());
    let k = key();
    let path = cache.put(&entry_for(k.clone(), 1.0)).expect("put");
    damage(&path, &cache);

    match cache.get(&k) {
        Err(CacheError::Corrupt { path: p, reason }) => {
            assert_eq!(p, path, "{case}: error names the wrong file");
            assert!(
                reason.contains(reason_part),
                "{case}: reason {reason:?} lacks {reason_part:?}"
            );
            let message = CacheError::Corrupt { path: p, reason }.to_string();
            assert!(
                message.contains(&k.file_name()),
                "{case}: message {message:?} does not name the file"
            );
        }
        other => panic!("{case}: expected Corrupt, got {other:?}"),
    }

    let fresh = entry_for(k.clone(), 3.0);
    let (got, provenance) = cache
        .get_or_compute(&k, || Ok::<_, TestError>(fresh.clone()))
        .unwrap_or_else(|e| panic!("{case}: get_or_compute: {e:?}"));
    assert_identical(&got, &fresh);
    match provenance {
        Provenance::RecomputedAfterCorrupt { reason } => {
            assert!(reason.contains(reason_part), "{case}: provenance reason {reason:?}")
        }
        other => panic!("{case}: expected RecomputedAfterCorrupt, got {other:?}"),
    }
    let after = cache
        .get(&k)
        .unwrap_or_else(|e| panic!("{case}: get after repair: {e}"));
    assert_identical(&after.expect("hit after repair"), &fresh);
}

#[test]
fn a_truncated_file_is_refused_and_recomputed() {
    check_corruption_is_detected_and_repaired("half the file", "checksum", |path, _| {
        // Cut at the first line end past the middle: whole lines, no checksum.
        let bytes = fs::read(path).expect("read");
        let half = bytes.len() / 2;
        let end = half + bytes[half..].iter().position(|&b| b == b'\n').expect("a line end");
        fs::write(path, &bytes[..=end]).expect("truncate");
    });
    check_corruption_is_detected_and_repaired("cut mid-line", "truncated", |path, _| {
        let bytes = fs::read(path).expect("read");
        let half = bytes.len() / 2;
        let end = half + bytes[half..].iter().position(|&b| b == b'\n').expect("a line end");
        fs::write(path, &bytes[..end - 1]).expect("truncate");
    });
    check_corruption_is_detected_and_repaired("last byte missing", "truncated", |path, _| {
        let bytes = fs::read(path).expect("read");
        fs::write(path, &bytes[..bytes.len() - 1]).expect("truncate");
    });
    check_corruption_is_detected_and_repaired("checksum line missing", "checksum line", |path, _| {
        let text = fs::read_to_string(path).expect("read");
        let (body, _) = text.trim_end_matches('\n').rsplit_once('\n').expect("lines");
        fs::write(path, format!("{body}\n")).expect("truncate");
    });
    check_corruption_is_detected_and_repaired("empty file", "empty", |path, _| {
        fs::write(path, b"").expect("truncate");
    });
}

#[test]
fn a_flipped_digit_in_a_coefficient_is_refused_and_recomputed() {
    check_corruption_is_detected_and_repaired("1000.0 -> 1001.0", "checksum mismatch", |path, _| {
        let text = fs::read_to_string(path).expect("read");
        assert!(text.contains("k = 1000.0"), "{text}");
        fs::write(path, text.replacen("k = 1000.0", "k = 1001.0", 1)).expect("write");
    });
}

#[test]
fn garbage_is_refused_and_recomputed() {
    check_corruption_is_detected_and_repaired("binary garbage", "not UTF-8", |path, _| {
        let mut rng = Rng::new(3);
        let bytes: Vec<u8> = (0..4096).map(|_| (rng.next_u64() >> 56) as u8 | 0x80).collect();
        fs::write(path, bytes).expect("write");
    });
    check_corruption_is_detected_and_repaired("text garbage", "checksum line", |path, _| {
        fs::write(path, "hello\nworld\n").expect("write");
    });
}

#[test]
fn another_keys_valid_file_under_this_name_is_refused_and_recomputed() {
    check_corruption_is_detected_and_repaired("copied from dt=1e-4", "another key: dt", |path, cache| {
        let mut other = key();
        other.dt = 1e-4;
        let other_path = cache.put(&entry_for(other, 9.0)).expect("put other");
        fs::copy(other_path, path).expect("copy over");
    });
}

#[test]
fn invalid_values_under_a_valid_checksum_are_refused_and_recomputed() {
    check_corruption_is_detected_and_repaired("negative stiffness", "structural_u stiffness k = -1000", |path, _| {
        // Someone edited the file and "fixed" the checksum.
        let text = fs::read_to_string(path).expect("read");
        let (body, _) = text.trim_end_matches('\n').rsplit_once('\n').expect("lines");
        let body = format!("{}\n", body.replacen("k = 1000.0", "k = -1000.0", 1));
        let sum = fnv1a64(body.as_bytes());
        fs::write(path, format!("{body}# checksum = fnv1a64:{sum:016x}\n")).expect("write");
    });
    check_corruption_is_detected_and_repaired("unknown field", "invalid TOML", |path, _| {
        let text = fs::read_to_string(path).expect("read");
        let (body, _) = text.trim_end_matches('\n').rsplit_once('\n').expect("lines");
        let body = body.replacen("format = 2", "format = 2\nsurprise = 2", 1);
        let body = format!("{body}\n");
        let sum = fnv1a64(body.as_bytes());
        fs::write(path, format!("{body}# checksum = fnv1a64:{sum:016x}\n")).expect("write");
    });
    // A file of the previous format (one value per spring kind), intact:
    // refused by its format, not by the first field that differs.
    check_corruption_is_detected_and_repaired("format 1", "cache format 1", |path, _| {
        let text = fs::read_to_string(path).expect("read");
        let (body, _) = text.trim_end_matches('\n').rsplit_once('\n').expect("lines");
        let body = body.replacen("format = 2", "format = 1", 1).replacen(
            "[material.structural_u]",
            "[material.structural]",
            1,
        );
        let body = format!("{body}\n");
        let sum = fnv1a64(body.as_bytes());
        fs::write(path, format!("{body}# checksum = fnv1a64:{sum:016x}\n")).expect("write");
    });
}

#[test]
fn put_refuses_entries_that_get_would_reject() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = open(dir.path());
    for (what, e) in [
        ("nan damping", {
            let mut e = entry_for(key(), 1.0);
            e.material.springs[1].c = f64::NAN;
            e
        }),
        ("zero stiffness with damping", {
            let mut e = entry_for(key(), 1.0);
            e.material.springs[2].k = 0.0;
            e.material.springs[2].c = 0.5;
            e
        }),
        ("infinite note", {
            let mut e = entry_for(key(), 1.0);
            e.notes.insert("x".into(), f64::INFINITY);
            e
        }),
    ] {
        match cache.put(&e) {
            Err(CacheError::Invalid { .. }) => {}
            other => panic!("{what}: expected Invalid, got {other:?}"),
        }
    }
    assert!(listing(dir.path()).is_empty(), "nothing written");
    // An absent spring type (K = C = 0, as a surface's shear) round-trips.
    let mut surface = entry_for(key(), 1.0);
    surface.material.springs[lodcloth::sim::SpringClass::Shear.index()] =
        lodcloth::sim::SpringCoeffs { k: 0.0, c: 0.0 };
    cache.put(&surface).expect("an absent type is valid");
    let back = cache.get(&key()).expect("readable").expect("present");
    assert_identical(&back, &surface);
}

// ---------------------------------------------------------------- get_or_compute

#[test]
fn get_or_compute_computes_once_then_hits() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = open(dir.path());
    let k = key();
    let e = entry_for(k.clone(), 1.0);
    let (got, p) = cache
        .get_or_compute(&k, || Ok::<_, TestError>(e.clone()))
        .expect("compute");
    assert_eq!(p, Provenance::Computed);
    assert_identical(&got, &e);

    // A restart (new handle) hits without computing.
    let cache = open(dir.path());
    let (got, p) = cache
        .get_or_compute(&k, || -> Result<CacheEntry, TestError> {
            panic!("must not recompute on a hit")
        })
        .expect("hit");
    assert_eq!(p, Provenance::Hit);
    assert_identical(&got, &e);
}

#[test]
fn get_or_compute_passes_compute_errors_through_and_stores_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = open(dir.path());
    match cache.get_or_compute(&key(), || Err(TestError::Compute("diverged"))) {
        Err(TestError::Compute("diverged")) => {}
        other => panic!("expected the compute error, got {other:?}"),
    }
    assert!(listing(dir.path()).is_empty());
}

#[test]
fn get_or_compute_refuses_an_entry_computed_for_another_key() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = open(dir.path());
    let mut other = key();
    other.target = (20, 20);
    match cache.get_or_compute(&key(), || Ok::<_, TestError>(entry_for(other.clone(), 1.0))) {
        Err(TestError::Cache(CacheError::Invalid { reason, .. })) => assert!(reason.contains("target"), "{reason}"),
        other => panic!("expected Invalid, got {other:?}"),
    }
    assert!(listing(dir.path()).is_empty());
}

// ---------------------------------------------------------------- temp files

/// The pid of a process that has exited and been reaped.
#[cfg(target_os = "linux")]
fn dead_pid() -> u32 {
    let mut child = std::process::Command::new("true").spawn().expect("spawn `true`");
    let pid = child.id();
    child.wait().expect("wait");
    pid
}

#[cfg(target_os = "linux")]
#[test]
fn open_removes_temp_files_of_dead_writers_and_old_ones_but_not_live_or_foreign_files() {
    let dir = tempfile::tempdir().expect("temp dir");
    let name = key().file_name();
    let dead = format!(".{name}.{}.0.tmp", dead_pid());
    let live_fresh = format!(".{name}.{}.999999.tmp", std::process::id());
    let live_old = format!(".{name}.{}.999998.tmp", std::process::id());
    let foreign = "notes.tmp".to_string();
    for f in [&dead, &live_fresh, &live_old, &foreign] {
        fs::write(dir.path().join(f), b"partial").expect("write");
    }
    let two_minutes_ago = SystemTime::now() - Duration::from_secs(120);
    fs::File::options()
        .write(true)
        .open(dir.path().join(&live_old))
        .and_then(|f| f.set_modified(two_minutes_ago))
        .expect("age the file");

    let cache = open(dir.path());
    let mut want = vec![live_fresh.clone(), foreign];
    want.sort();
    assert_eq!(listing(dir.path()), want);
    assert_eq!(cache.remove_stale_temp_files().expect("clean"), 0, "idempotent");
}

// ---------------------------------------------------------------- kill -9

/// Set for the child process of the kill test: the cache directory to write to.
const KILL_DIR_ENV: &str = "LODCLOTH_CACHE_KILL_TEST_DIR";
const KILL_HELPER: &str = "kill_helper_writes_alternating_large_entries_forever";

/// The helper's full test name in this binary (`cache::…` inside
/// tests/sim.rs): `--exact` matches nothing otherwise, and the helper would
/// exit at once.
fn kill_helper_name() -> String {
    match module_path!().split_once("::") {
        Some((_crate, module)) => format!("{module}::{KILL_HELPER}"),
        None => KILL_HELPER.to_string(),
    }
}

/// Two large entries (≈ 1 MB each) for the same key, so that each write takes
/// a while. The bulk is in long note names rather than many notes, so that
/// encoding (done before the temporary file exists) is cheap next to writing
/// and syncing, and kills often land inside a write.
fn large_entries() -> [CacheEntry; 2] {
    let big = |scale: f64| {
        let mut e = entry_for(key(), scale);
        let mut rng = Rng::new(scale.to_bits());
        let padding = "residual of a sample ".repeat(250);
        for i in 0..200 {
            e.notes.insert(format!("{i:03} {padding}"), rng.uniform(-1.0, 1.0));
        }
        e
    };
    [big(1.0), big(2.0)]
}

/// Not a test on its own: the kill test runs this binary again with only this
/// function selected and `KILL_DIR_ENV` set, and kills it.
#[test]
#[ignore = "helper process for the kill test; does nothing when run by hand"]
fn kill_helper_writes_alternating_large_entries_forever() {
    let Some(dir) = std::env::var_os(KILL_DIR_ENV) else {
        return;
    };
    let cache = open(Path::new(&dir));
    let entries = large_entries();
    loop {
        for e in &entries {
            cache.put(e).expect("put");
        }
    }
}

#[cfg(unix)]
#[test]
fn a_writer_killed_at_any_moment_leaves_the_old_or_the_new_file_never_a_torn_one() {
    use std::process::{Command, Stdio};

    let dir = tempfile::tempdir().expect("temp dir");
    let exe: PathBuf = std::env::current_exe().expect("test binary path");
    let entries = large_entries();
    let k = key();
    let final_name = k.file_name();
    let mut rng = Rng::new(2024);
    let (mut found_file, mut mid_write_kills, mut found) = (false, 0, [0usize; 2]);
    // Kill at random moments until enough kills have landed inside a write
    // (between creating the temporary file and renaming it, about a fifth of
    // the writer's time): at least MIN_ROUNDS rounds, at most MAX_ROUNDS.
    const MIN_ROUNDS: usize = 30;
    const MAX_ROUNDS: usize = 400;
    const MIN_MID_WRITE_KILLS: usize = 5;
    let mut rounds = 0;
    while rounds < MIN_ROUNDS || (mid_write_kills < MIN_MID_WRITE_KILLS && rounds < MAX_ROUNDS) {
        let round = rounds;
        rounds += 1;
        let mut child = Command::new(&exe)
            .args([&kill_helper_name(), "--exact", "--ignored", "--test-threads=1"])
            .env(KILL_DIR_ENV, dir.path())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn the writer");
        // From "before the first write" (start-up takes a few ms) to several writes in.
        let delay = Duration::from_micros(rng.uniform(0.0, 60_000.0) as u64);
        std::thread::sleep(delay);
        if let Ok(Some(status)) = child.try_wait() {
            panic!("round {round}: the writer exited by itself ({status})");
        }
        child.kill().expect("SIGKILL the writer");
        child.wait().expect("reap the writer");

        let names = listing(dir.path());
        let temps = names.iter().filter(|n| n.ends_with(".tmp")).count();
        mid_write_kills += usize::from(temps > 0);
        for n in &names {
            assert!(
                n == &final_name || n.ends_with(".tmp"),
                "round {round}: unexpected file {n}"
            );
        }

        // A restart: open cleans up, get sees a whole file.
        let cache = open(dir.path());
        #[cfg(target_os = "linux")]
        assert_eq!(
            listing(dir.path()).iter().filter(|n| n.ends_with(".tmp")).count(),
            0,
            "round {round}: temp files of the dead writer survived open"
        );
        match cache.get(&k) {
            Ok(None) => assert!(!found_file, "round {round}: the cache file vanished"),
            Ok(Some(got)) => {
                found_file = true;
                let i = entries
                    .iter()
                    .position(|e| e == &got)
                    .unwrap_or_else(|| panic!("round {round}: read an entry that was never written"));
                assert_identical(&got, &entries[i]);
                found[i] += 1;
            }
            Err(e) => panic!("round {round} (killed after {delay:?}): {e}"),
        }
    }
    eprintln!(
        "{rounds} kills: {mid_write_kills} left a temp file (killed mid-write), read entry A {} times, B {} times",
        found[0], found[1]
    );
    assert!(
        found_file,
        "the writer never completed a write in {rounds} rounds: delays too short for this machine"
    );
    assert!(
        mid_write_kills >= MIN_MID_WRITE_KILLS,
        "only {mid_write_kills} of {rounds} kills landed during a write: the test proved too little"
    );
}
