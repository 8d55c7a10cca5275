//! The response table the firmware embeds (`src/estimator/table.rs`) is the
//! simulator's: this test rebuilds it from `fois_sim::table` with the default
//! spec and fails if the checked-in file differs. `FOIS_BLESS=1` rewrites it.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use fois_sim::table::{REGENERATE, TableSpec, build_table, to_rust_source};

#[test]
fn checked_in_table_is_the_simulators() {
    let spec = TableSpec::default();
    let table = build_table(&spec, &|| {}).expect("the default table spec is valid");
    let fresh = to_rust_source(&table, REGENERATE).expect("the table fits its packing");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/estimator/table.rs");
    if std::env::var("FOIS_BLESS").is_ok_and(|v| v == "1") {
        std::fs::write(&path, &fresh).expect("write the table");
        eprintln!("wrote {}", path.display());
        return;
    }
    let current = std::fs::read_to_string(&path).unwrap_or_default();
    if current != fresh {
        let line = current
            .lines()
            .zip(fresh.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(current.lines().count().min(fresh.lines().count()));
        panic!(
            "the checked-in response table is stale (first difference at line {}):\n  checked in: {:?}\n  simulator:  {:?}\nregenerate it with\n  {REGENERATE}",
            line + 1,
            current.lines().nth(line).unwrap_or("<end of file>"),
            fresh.lines().nth(line).unwrap_or("<end of file>"),
        );
    }
}
