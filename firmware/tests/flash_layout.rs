//! The two linker scripts (the application's `firmware/board/memory.x`, the
//! bootloader's `boot/memory.x`) say what `platform::flash_layout` says:
//! one source for the partitions, checked here.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use fois_firmware::platform::flash_layout::{
    ACTIVE, BOOT_STATE, BOOTLOADER, CONFIG_STORE, DFU, FLASH_BASE,
};
use fois_firmware::storage::flash_store::BOARD_SECTOR_BYTES;

/// A number of a linker script: `0x…`, decimal, or with a `K` suffix.
fn number(text: &str) -> u32 {
    let t = text.trim().trim_end_matches(';').trim();
    if let Some(k) = t.strip_suffix('K') {
        return k.trim().parse::<u32>().unwrap() * 1024;
    }
    match t.strip_prefix("0x") {
        Some(hex) => u32::from_str_radix(hex, 16).unwrap(),
        None => t.parse().unwrap(),
    }
}

/// `name : ORIGIN = a, LENGTH = b` of a MEMORY region.
fn region(script: &str, name: &str) -> (u32, u32) {
    let line = script
        .lines()
        .find(|l| l.trim_start().starts_with(name) && l.contains("ORIGIN"))
        .unwrap_or_else(|| panic!("no region {name}"));
    let origin = line.split("ORIGIN").nth(1).unwrap();
    let origin = origin
        .trim_start_matches([' ', '='])
        .split(',')
        .next()
        .unwrap();
    let length = line
        .split("LENGTH")
        .nth(1)
        .unwrap()
        .trim_start_matches([' ', '=']);
    (number(origin), number(length))
}

/// `symbol = value;`
fn symbol(script: &str, name: &str) -> u32 {
    let line = script
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("{name} =")))
        .unwrap_or_else(|| panic!("no symbol {name}"));
    number(line.split('=').nth(1).unwrap())
}

fn read(path: &str) -> String {
    std::fs::read_to_string(format!("{}/{path}", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

#[test]
fn the_applications_memory_x_is_the_active_slot() {
    let app = read("board/memory.x");
    assert_eq!(region(&app, "FLASH"), (ACTIVE.start(), ACTIVE.bytes()));
    assert_eq!(region(&app, "RAM"), (0x2000_0000, 32 * 1024));
    // embassy-boot's names, as offsets from the start of flash.
    assert_eq!(
        symbol(&app, "__bootloader_state_start"),
        BOOT_STATE.offset()
    );
    assert_eq!(
        symbol(&app, "__bootloader_state_end"),
        BOOT_STATE.end() - FLASH_BASE
    );
    assert_eq!(symbol(&app, "__bootloader_dfu_start"), DFU.offset());
    assert_eq!(symbol(&app, "__bootloader_dfu_end"), DFU.end() - FLASH_BASE);
}

#[test]
fn the_bootloaders_memory_x_is_sectors_0_and_1() {
    let boot = read("../boot/memory.x");
    assert_eq!(
        region(&boot, "FLASH"),
        (BOOTLOADER.start(), BOOTLOADER.bytes())
    );
    assert_eq!(region(&boot, "RAM"), (0x2000_0000, 32 * 1024));
    for (name, part) in [("state", BOOT_STATE), ("active", ACTIVE), ("dfu", DFU)] {
        assert_eq!(
            symbol(&boot, &format!("__bootloader_{name}_start")),
            part.offset(),
            "{name}"
        );
        assert_eq!(
            symbol(&boot, &format!("__bootloader_{name}_end")),
            part.end() - FLASH_BASE,
            "{name}"
        );
    }
}

#[test]
fn the_store_is_two_sectors_of_its_partition() {
    assert_eq!(BOARD_SECTOR_BYTES as u32 * 2, CONFIG_STORE.bytes());
    assert_eq!(CONFIG_STORE.start(), 0x0800_8000);
}
