//! The board image's linker settings: its `memory.x` (the active slot at
//! 0x0802_0000, `src/platform/flash_layout.rs`) first on the linker search
//! path, and defmt's linker script. Only for the board binary on the thumb
//! target: host builds, the QEMU test image and the bootloader (which use
//! the library with the `board` feature off) get nothing from here.
use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    let board = env::var_os("CARGO_FEATURE_BOARD").is_some();
    let thumb = env::var("TARGET").is_ok_and(|t| t.starts_with("thumb"));
    if !(board && thumb) {
        return;
    }
    let Some(out) = env::var_os("OUT_DIR").map(PathBuf::from) else {
        panic!("cargo sets OUT_DIR for build scripts");
    };
    if let Err(e) = fs::write(out.join("memory.x"), include_bytes!("memory.x")) {
        panic!("cannot write memory.x into {}: {e}", out.display());
    }
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
