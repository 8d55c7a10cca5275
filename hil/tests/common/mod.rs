//! What the scenario tests share: run one shipped scenario file with its
//! own expectations checked.
#![allow(dead_code)]

use fois_hil::{Outcome, Scenario, check, scenario};

/// Run one shipped scenario file (`hil/scenarios/FILE`); its own
/// expectations must hold too. The scenario comes back with the outcome.
pub fn run_file(file: &str) -> (Outcome, Scenario) {
    let path = scenario::default_dir().join(file);
    let mut scenarios = scenario::load(&path).expect("the scenario loads");
    assert_eq!(scenarios.len(), 1, "{file}: one run");
    let sc = scenarios.remove(0);
    let o = fois_hil::run(&sc).expect("the scenario runs");
    let failures = check::check(&sc, &o);
    assert!(failures.is_empty(), "{file}: {}", failures.join("; "));
    (o, sc)
}
