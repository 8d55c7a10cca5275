//! The bootloader's linker settings: its `memory.x` (sectors 0–1) first on
//! the linker search path, and defmt's linker script with the `defmt`
//! feature. Only on the thumb target.
use std::env;

#[path = "../firmware/board/memory_x.rs"]
mod memory_x;

fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    if !env::var("TARGET").is_ok_and(|t| t.starts_with("thumb")) {
        return;
    }
    memory_x::place_memory_x(include_bytes!("memory.x"));
    if env::var_os("CARGO_FEATURE_DEFMT").is_some() {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
