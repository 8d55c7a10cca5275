//! `foisctl virtual-node --state` with a state file of the layout before
//! the bootloader (the store on two 128 KiB sectors): not refused, its
//! record migrated by the firmware's `storage::migrate`, the user told
//! once, the file rewritten in the new 2 × 16 KiB layout.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;

use fois_firmware::Storage;
use fois_firmware::storage::flash_store::FlashStore;
use fois_firmware::storage::ram_flash::RamFlash;
use fois_firmware::storage::record;

const BIN: &str = env!("CARGO_BIN_EXE_foisctl");
const OLD_SECTOR: usize = 128 * 1024;

fn run_node(state: &std::path::Path) -> String {
    let out = Command::new(BIN)
        .args(["virtual-node", "--duration", "0.3", "--state"])
        .arg(state)
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn an_old_state_file_is_migrated_and_the_user_told_once() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("node.state");
    let rec = fois_vnode::node::factory_record(0.85, 0.03);
    let mut bytes = [0u8; record::MAX_RECORD];
    let n = record::encode(&rec, &mut bytes);
    let old = RamFlash::<Vec<u8>, OLD_SECTOR, 2>::new(vec![0xFF; 2 * OLD_SECTOR]);
    let mut store = FlashStore::new(old, 0..2 * OLD_SECTOR as u32).unwrap();
    store.write(&bytes[..n]).unwrap();
    std::fs::write(&state, store.flash_mut().bytes()).unwrap();

    let err = run_node(&state);
    assert!(
        err.contains("was of the layout before the bootloader") && err.contains("moved"),
        "{err}"
    );
    assert_eq!(std::fs::metadata(&state).unwrap().len(), 32 * 1024);
    let (storage, _) = fois_vnode::SharedStorage::open_file(&state).unwrap();
    let mut buf = [0u8; record::MAX_RECORD];
    let m = storage.snapshot().read(&mut buf).unwrap();
    assert_eq!(record::decode(&buf[..m]).unwrap(), rec);
    // Once: the next start reads the new layout without a word.
    let err = run_node(&state);
    assert!(!err.contains("layout before the bootloader"), "{err}");
}
