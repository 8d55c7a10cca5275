//! Every scenario file in `hil/scenarios/` must meet its expectations.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::time::Instant;

use fois_hil::{report, run, scenario};

#[test]
fn every_scenario_meets_its_expectations() {
    let scenarios = scenario::load_dir(&scenario::default_dir()).expect("scenario files load");
    assert!(scenarios.len() >= 3, "only {} scenarios", scenarios.len());
    let start = Instant::now();
    let results = run::run_all(&scenarios, run::default_threads());
    let wall = start.elapsed();
    let mut outcomes = Vec::new();
    let mut failed = Vec::new();
    for (sc, r) in scenarios.iter().zip(results) {
        match r {
            Ok(o) => {
                if !o.failures.is_empty() {
                    failed.push(format!("{}: {}", sc.name, o.failures.join("; ")));
                }
                outcomes.push(o);
            }
            Err(e) => failed.push(format!("{}: {e:#}", sc.name)),
        }
    }
    println!("{}", report::table(&outcomes));
    println!("{}", report::goals_summary(&outcomes));
    println!("{} runs in {:.1} s", outcomes.len(), wall.as_secs_f64());
    assert!(failed.is_empty(), "{}", failed.join("\n"));
    let _ = Path::new(".");
}
