//! The crate rules of ARCHITECTURE.md ("Crates and their arrows"),
//! checked on the real dependency graph (`cargo tree`): a new dependency
//! that breaks one fails CI with the path that breaks it.
//!
//! | rule | why |
//! | --- | --- |
//! | nothing depends on `fois-host`, `fois-gateway` or `fois-node` (any edge: normal, build, dev) | they are the tops of the graph: an operator's tool, a service and the board's image |
//! | `fois-sim` depends on no FOIS crate | the simulator knows nothing of firmware or protocol |
//! | `fois-protocol` depends on no FOIS crate; `fois-firmware` only on `fois-protocol` | the node's contract and logic stand alone |
//! | `fois-protocol` and `fois-firmware` are `no_std` (their `lib.rs` says so) and pull no host crate for the thumb target | they run on the Cortex-M4F |
//! | `foisctl` (`fois-host`) holds no tokio, rumqttc, rustls | the async MQTT stack is the gateway's |
//! | `fois-link` holds no tokio, rumqttc, rustls, vnode, sim, firmware | `foisctl` and the gateway share it: it stays small |
//! | `fois-gateway` holds no vnode, sim, firmware, plotters, indicatif | a service on a site computer, not the simulator |
//! | `fois-hil` holds no clap, serialport, plotters, indicatif | the suite runs the node, not the CLI |
//! | `xtask` depends on no FOIS crate | it runs cargo |
//! | `fois-node` depends on no FOIS crate but `fois-firmware` and `fois-protocol`, and on no host crate | the board's image is the library's logic and the HAL around it |
//! | `fois-boot` depends on no FOIS crate, no sequential-storage, postcard or defmt (default features) | the bootloader cannot be updated over the link: small, no log, the flash layout and the flash controller's steps shared by their source files |

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result, bail};

/// A rule: the packages `package`'s graph (over `edges`, for `target`)
/// must not contain. `fois-*` stands for every FOIS crate but those in
/// `allowed`.
#[derive(Debug, Clone, Copy)]
pub struct Rule {
    /// The package whose graph is checked.
    pub package: &'static str,
    /// `cargo tree -e` edge kinds.
    pub edges: &'static str,
    /// `--target`, if not the host.
    pub target: Option<&'static str>,
    /// Packages that must not appear (`fois-*`: any FOIS crate).
    pub forbidden: &'static [&'static str],
    /// FOIS crates allowed despite `fois-*`.
    pub allowed: &'static [&'static str],
    /// Why (printed with a violation).
    pub why: &'static str,
}

/// What a crate that runs on the Cortex-M4F must not pull in: any FOIS
/// crate but those its rule allows, and the host's runtime, network and
/// command-line crates.
const ON_THE_CHIP: &[&str] = &[
    "fois-*",
    "tokio",
    "rumqttc",
    "rustls",
    "clap",
    "rayon",
    "serialport",
];

/// Every downward rule of ARCHITECTURE.md.
pub const RULES: [Rule; 10] = [
    Rule {
        package: "fois-sim",
        edges: "normal,build",
        target: None,
        forbidden: &["fois-*"],
        allowed: &[],
        why: "the simulator depends on no FOIS crate",
    },
    Rule {
        package: "fois-protocol",
        edges: "normal,build",
        target: Some("thumbv7em-none-eabihf"),
        forbidden: ON_THE_CHIP,
        allowed: &[],
        why: "the protocol is no_std and stands alone",
    },
    Rule {
        package: "fois-firmware",
        edges: "normal,build",
        target: Some("thumbv7em-none-eabihf"),
        forbidden: ON_THE_CHIP,
        allowed: &["fois-protocol"],
        why: "the firmware is no_std and depends only on the protocol",
    },
    Rule {
        package: "fois-host",
        edges: "normal,build",
        target: None,
        forbidden: &["tokio", "rumqttc", "rustls", "fois-gateway"],
        allowed: &[],
        why: "foisctl carries no async MQTT stack (that is the gateway's)",
    },
    Rule {
        package: "fois-link",
        edges: "normal,build",
        target: None,
        forbidden: &["tokio", "rumqttc", "rustls", "fois-*"],
        allowed: &["fois-protocol"],
        why: "the link crate that foisctl and the gateway share stays small",
    },
    Rule {
        package: "fois-gateway",
        edges: "normal,build",
        target: None,
        forbidden: &["fois-*", "plotters", "indicatif"],
        allowed: &["fois-protocol", "fois-link"],
        why: "the gateway is a service: no simulator, no virtual node, no figures",
    },
    Rule {
        package: "fois-hil",
        edges: "normal,build",
        target: None,
        forbidden: &["clap", "serialport", "plotters", "indicatif"],
        allowed: &[],
        why: "the HIL suite runs the node, not the command line",
    },
    Rule {
        package: "xtask",
        edges: "normal,build",
        target: None,
        forbidden: &["fois-*"],
        allowed: &[],
        why: "xtask runs cargo, it links no FOIS crate",
    },
    Rule {
        package: "fois-node",
        edges: "normal,build",
        target: Some("thumbv7em-none-eabihf"),
        forbidden: ON_THE_CHIP,
        allowed: &["fois-firmware", "fois-protocol"],
        why: "the board's image is the library's logic and the HAL around it",
    },
    Rule {
        package: "fois-boot",
        edges: "normal,build",
        target: Some("thumbv7em-none-eabihf"),
        forbidden: &["fois-*", "sequential-storage", "postcard", "defmt"],
        allowed: &[],
        why: "the bootloader is never updated in the field: it stays small and links no FOIS crate \
              (it shares the flash layout's and the flash controller's source files) and no log by default",
    },
];

/// Packages nothing may depend on, over any edge.
pub const TOPS: [&str; 3] = ["fois-host", "fois-gateway", "fois-node"];

/// Crates whose `lib.rs` must declare `no_std`.
pub const NO_STD: [(&str, &str); 2] = [
    ("fois-protocol", "protocol/src/lib.rs"),
    ("fois-firmware", "firmware/src/lib.rs"),
];

/// The package names in a `cargo tree --prefix none --format {p}` output.
pub fn names(tree: &str) -> BTreeSet<String> {
    tree.lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_string)
        .collect()
}

/// What of `deps` breaks `rule` (the package itself aside).
pub fn violations(rule: &Rule, deps: &BTreeSet<String>) -> Vec<String> {
    deps.iter()
        .filter(|d| d.as_str() != rule.package)
        .filter(|d| {
            rule.forbidden.iter().any(|f| match f.strip_suffix('*') {
                Some(prefix) => d.starts_with(prefix) && !rule.allowed.contains(&d.as_str()),
                None => d.as_str() == *f,
            })
        })
        .cloned()
        .collect()
}

/// The packages that depend on `package` (`cargo tree -i`), itself aside.
pub fn dependents(package: &str, tree: &str) -> Vec<String> {
    names(tree).into_iter().filter(|n| n != package).collect()
}

/// True when a `lib.rs` declares `no_std` (always, or outside tests/std).
pub fn declares_no_std(lib_rs: &str) -> bool {
    lib_rs.lines().any(|l| {
        let l = l.trim();
        l.starts_with("#![") && l.contains("no_std")
    })
}

fn cargo_tree(args: &[&str]) -> Result<String> {
    let out = Command::new("cargo")
        .arg("tree")
        .args(args)
        .args(["--prefix", "none", "--format", "{p}"])
        .output()
        .context("could not run cargo tree")?;
    if !out.status.success() {
        bail!(
            "`cargo tree {}` failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Check every rule; the list of what is wrong, or Ok.
pub fn check(root: &Path) -> Result<()> {
    let mut wrong = Vec::new();
    for rule in &RULES {
        let mut args = vec!["-p", rule.package, "-e", rule.edges];
        if let Some(t) = rule.target {
            args.extend(["--target", t]);
        }
        let deps = names(&cargo_tree(&args)?);
        for v in violations(rule, &deps) {
            wrong.push(format!(
                "{} depends on {v} (`cargo tree -p {} -e {} -i {v}` shows the path): {}",
                rule.package, rule.package, rule.edges, rule.why
            ));
        }
    }
    for top in TOPS {
        let tree = cargo_tree(&["--workspace", "-e", "normal,build,dev", "-i", top])?;
        for d in dependents(top, &tree) {
            wrong.push(format!(
                "{d} depends on {top}: nothing may depend on it (it is the top of the graph)"
            ));
        }
    }
    for (package, lib) in NO_STD {
        let text = std::fs::read_to_string(root.join(lib))
            .with_context(|| format!("cannot read {lib}"))?;
        if !declares_no_std(&text) {
            wrong.push(format!("{package} ({lib}) does not declare no_std"));
        }
    }
    if !wrong.is_empty() {
        bail!(
            "the crate rules of ARCHITECTURE.md are broken:\n  {}",
            wrong.join("\n  ")
        );
    }
    eprintln!(
        "crate rules: {} dependency rules, nothing depends on {}, {} no_std crates: all hold",
        RULES.len(),
        TOPS.join(" or "),
        NO_STD.len()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(names: &[&str]) -> BTreeSet<String> {
        names.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_forbidden_crate_is_named_and_allowed_ones_are_not() {
        let gw = RULES.iter().find(|r| r.package == "fois-gateway").unwrap();
        let ok = set(&[
            "fois-gateway",
            "fois-link",
            "fois-protocol",
            "tokio",
            "rumqttc",
        ]);
        assert!(violations(gw, &ok).is_empty());
        let bad = set(&[
            "fois-gateway",
            "fois-link",
            "fois-vnode",
            "fois-sim",
            "plotters",
        ]);
        assert_eq!(
            violations(gw, &bad),
            vec!["fois-sim", "fois-vnode", "plotters"]
        );
        let host = RULES.iter().find(|r| r.package == "fois-host").unwrap();
        assert_eq!(
            violations(host, &set(&["fois-host", "fois-link", "tokio", "mio"])),
            vec!["tokio"]
        );
    }

    #[test]
    fn cargo_tree_lines_give_package_names_and_dependents() {
        let tree = "fois-host v0.1.0 (/r/host)\nfois-gateway v0.1.0 (/r/gateway)\n\
                    fois-host v0.1.0 (/r/host)\n";
        assert_eq!(dependents("fois-host", tree), vec!["fois-gateway"]);
        assert!(dependents("fois-host", "fois-host v0.1.0 (/r/host)\n").is_empty());
    }

    #[test]
    fn no_std_is_recognised_in_both_forms() {
        assert!(declares_no_std("//! doc\n#![no_std]\n"));
        assert!(declares_no_std(
            "#![cfg_attr(not(any(feature = \"std\", test)), no_std)]\n"
        ));
        assert!(!declares_no_std(
            "//! works without no_std? no\nfn main() {}\n"
        ));
    }
}
