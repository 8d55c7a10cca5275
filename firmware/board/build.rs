//! The update key (every build: `$OUT_DIR/update_key.rs`, the board's
//! `UPDATE_KEY`) and the board image's linker settings: its `memory.x` (the
//! active slot at 0x0802_0000, fois-firmware's `platform/flash_layout.rs`)
//! first on the linker search path, and defmt's linker script. The linker
//! settings only on the thumb target: on the host the binary is a stub.
use std::{env, fs, path::PathBuf};

#[path = "memory_x.rs"]
mod memory_x;

fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    update_key();
    if !env::var("TARGET").is_ok_and(|t| t.starts_with("thumb")) {
        return;
    }
    memory_x::place_memory_x(include_bytes!("memory.x"));
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}

/// The public key the board verifies images with, from the file named by
/// `FOIS_UPDATE_PUBLIC_KEY`, else `firmware/keys/fois-update.pub` (64 hex digits,
/// what `foisctl keygen` writes), written as a Rust expression of type
/// `Option<[u8; 32]>` into `$OUT_DIR/update_key.rs`. Without a file the
/// expression is `None`: the image refuses every update (a warning says
/// so). A file that is not a key fails the build.
fn update_key() {
    println!("cargo:rerun-if-env-changed=FOIS_UPDATE_PUBLIC_KEY");
    let default = PathBuf::from("../keys/fois-update.pub");
    println!("cargo:rerun-if-changed={}", default.display());
    let named = env::var_os("FOIS_UPDATE_PUBLIC_KEY").map(PathBuf::from);
    let path = named.clone().unwrap_or(default);
    let expr = match fs::read_to_string(&path) {
        Ok(text) => {
            println!("cargo:rerun-if-changed={}", path.display());
            let hex = text.trim();
            let bytes: Option<Vec<u8>> = (hex.len() == 64 && hex.is_ascii())
                .then(|| {
                    (0..32)
                        .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok())
                        .collect()
                })
                .flatten();
            match bytes {
                Some(b) => format!("Some({b:?})"),
                None => panic!(
                    "{}: not an update public key (64 hex digits, as `foisctl keygen` writes)",
                    path.display()
                ),
            }
        }
        Err(e) if named.is_some() => {
            panic!("FOIS_UPDATE_PUBLIC_KEY={}: {e}", path.display())
        }
        Err(_) => {
            let board = env::var_os("CARGO_FEATURE_UPDATER").is_some();
            let thumb = env::var("TARGET").is_ok_and(|t| t.starts_with("thumb"));
            if board && thumb {
                println!(
                    "cargo:warning=no update key (firmware/keys/fois-update.pub or FOIS_UPDATE_PUBLIC_KEY): \
                     this image refuses every firmware update"
                );
            }
            "None".to_string()
        }
    };
    let Some(out) = env::var_os("OUT_DIR").map(PathBuf::from) else {
        panic!("cargo sets OUT_DIR for build scripts");
    };
    if let Err(e) = fs::write(out.join("update_key.rs"), expr) {
        panic!("cannot write update_key.rs into {}: {e}", out.display());
    }
}
