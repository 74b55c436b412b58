//! Compiles the wire contract in `proto/` with protox (a pure-Rust protobuf
//! compiler), so building needs no system `protoc`. The file descriptor set
//! is kept too (`lodcloth.fds`): Foxglove channels carry it as their schema.
//!
//! Also records the git revision the binary was built from
//! (`LODCLOTH_GIT_REVISION`, shown by `lodcloth --version` and the
//! `lodcloth_build_info` metric): `git rev-parse` when the source is a
//! checkout, else the variable of the same name from the environment (the
//! Dockerfile's build argument, as its context has no `.git`), else
//! `unknown`.

use std::path::Path;
use std::process::Command;

use prost::Message;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let files = ["proto/lodcloth/v1/lodcloth.proto"];
    for f in files {
        println!("cargo:rerun-if-changed={f}");
    }
    let descriptors = protox::compile(files, ["proto"])?;
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(out.join("lodcloth.fds"), descriptors.encode_to_vec())?;
    prost_build::Config::new().compile_fds(descriptors)?;
    println!("cargo:rustc-env=LODCLOTH_GIT_REVISION={}", revision());
    Ok(())
}

/// The checkout's commit (12 hex digits), or the environment's, or `unknown`.
/// Reruns when HEAD moves (a commit, a checkout); not when the work tree
/// changes, which would rebuild the crate at every `git status`.
fn revision() -> String {
    println!("cargo:rerun-if-env-changed=LODCLOTH_GIT_REVISION");
    let git = |args: &[&str]| {
        Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .and_then(|o| String::from_utf8(o.stdout).ok())
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
    };
    if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
        let dir = Path::new(&dir);
        // Only files that exist: cargo reruns a script whose listed file is
        // missing at every build.
        let head_ref = git(&["symbolic-ref", "-q", "HEAD"]);
        let watched = ["HEAD", "packed-refs"].into_iter().chain(head_ref.as_deref());
        for f in watched.map(|f| dir.join(f)).filter(|f| f.exists()) {
            println!("cargo:rerun-if-changed={}", f.display());
        }
        if let Some(rev) = git(&["rev-parse", "--short=12", "HEAD"]) {
            return rev;
        }
    }
    std::env::var("LODCLOTH_GIT_REVISION")
        .ok()
        .filter(|s| !s.trim().is_empty())
        .unwrap_or_else(|| "unknown".into())
}
