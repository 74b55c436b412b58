//! Compiles the wire contract in `proto/` with protox (a pure-Rust protobuf
//! compiler), so building needs no system `protoc`. The file descriptor set
//! is kept too (`lodcloth.fds`): Foxglove channels carry it as their schema.

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
    Ok(())
}
