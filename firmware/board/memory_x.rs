//! Shared by the build scripts of the board image (`firmware/board/build.rs`)
//! and the bootloader (`boot/build.rs`, by its path): a `memory.x` written
//! into `OUT_DIR` and that directory put first on the linker search path.
use std::{env, fs, path::PathBuf};

/// Write `memory_x` as `$OUT_DIR/memory.x` and search `OUT_DIR` first.
pub fn place_memory_x(memory_x: &[u8]) {
    let Some(out) = env::var_os("OUT_DIR").map(PathBuf::from) else {
        panic!("cargo sets OUT_DIR for build scripts");
    };
    if let Err(e) = fs::write(out.join("memory.x"), memory_x) {
        panic!("cannot write memory.x into {}: {e}", out.display());
    }
    println!("cargo:rustc-link-search={}", out.display());
}
