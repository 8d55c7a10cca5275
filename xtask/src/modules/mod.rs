//! The module rule of ARCHITECTURE.md: no two files of a crate import each
//! other, directly or around a loop.
//!
//! For every crate root under a workspace member's `src/` (`lib.rs`,
//! `main.rs`, `bin/*.rs`, `bin/*/main.rs`) the module tree is walked
//! through its `mod foo;` declarations (`foo.rs`, `foo/mod.rs`, a
//! `#[path = "…"]` if given; inline `mod foo { … }` blocks belong to their
//! file). Each file is read with a small lexer that drops comments and the
//! contents of string and character literals, then scanned for the paths
//! that reach another module of the crate: `use` trees and `crate::…`,
//! `super::…`, `self::…` paths anywhere, and paths through a child module's
//! name (`foo::bar`). A path is resolved to the file that defines its item:
//! the longest prefix that names a module, then through that module's
//! `use` re-exports (named or glob) when the item is not defined there. So
//! `use crate::Outcome` counts against the file that defines `Outcome`, not
//! against `lib.rs` that re-exports it.
//!
//! The edges form a file-level graph per crate root; every strongly
//! connected component of more than one file is a circle (each circle of
//! files lies in one), reported with the imports that close it. Rules:
//! a `mod b;` declaration alone is not an import (a parent declaring its
//! children is a tree); a child that uses its parent's items while the
//! parent uses the child's is a circle; an inline `mod tests { use
//! super::*; }` uses its own file, which is no edge at all; test code is
//! code (a `#[cfg(test)]` import is an import: a test that needs a higher
//! module lives in a file of its own, e.g. `setup/tests.rs`). Method calls
//! name no module and are no edge.
//!
//! [`KNOWN_CIRCLES`] lists the circles allowed, each with its reason (none
//! today); an entry that no longer matches a circle fails the check too.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use graph::Graph;

mod graph;
mod lex;
mod parse;

/// Circles allowed, each with the reason a circle is the right design
/// there: the full set of files of one circle (repository-relative). None
/// today. An entry that matches no circle any more fails the check, so the
/// list only shrinks.
pub const KNOWN_CIRCLES: &[&[&str]] = &[];

/// Check every workspace member's crates; fail on a circle not in
/// [`KNOWN_CIRCLES`] or an entry of it that matches no circle. With
/// `print_graph`, print every file and its imports first.
pub fn check(root: &Path, print_graph: bool) -> Result<()> {
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).context("Cargo.toml")?;
    let members = workspace_members(&manifest);
    if members.is_empty() {
        bail!("no workspace members found in Cargo.toml");
    }
    let mut failures = String::new();
    let mut matched = BTreeSet::new();
    let (mut roots, mut files, mut edges) = (0usize, 0usize, 0usize);
    for member in &members {
        for crate_root in crate_roots(&root.join(member).join("src")) {
            let graph = Graph::load(root, &crate_root)?;
            if print_graph {
                print!("{}", graph.listing());
            }
            roots += 1;
            files += graph.files.len();
            edges += graph.edges.values().map(BTreeMap::len).sum::<usize>();
            for circle in graph.circles() {
                let names: BTreeSet<&str> =
                    circle.iter().map(|&f| graph.files[f].as_str()).collect();
                let known = KNOWN_CIRCLES
                    .iter()
                    .position(|k| k.iter().copied().collect::<BTreeSet<_>>() == names);
                let text = graph.describe(&circle);
                match known {
                    Some(k) => {
                        matched.insert(k);
                        eprintln!("allowed circle (see KNOWN_CIRCLES):\n{text}");
                    }
                    None => failures.push_str(&text),
                }
            }
        }
    }
    for (k, entry) in KNOWN_CIRCLES.iter().enumerate() {
        if !matched.contains(&k) {
            let _ = writeln!(
                failures,
                "KNOWN_CIRCLES entry {entry:?} matches no circle any more: remove it"
            );
        }
    }
    if !failures.is_empty() {
        bail!("module circles (no two files of a crate may import each other):\n{failures}");
    }
    let allowed = match KNOWN_CIRCLES.len() {
        0 => "no circles".to_string(),
        n => format!("no circles beyond the {n} allowed"),
    };
    eprintln!(
        "module rule: {} packages, {roots} crate roots, {files} files, {edges} file imports, \
         {allowed}",
        members.len(),
    );
    Ok(())
}

/// The `members = [...]` of the workspace manifest.
fn workspace_members(manifest: &str) -> Vec<String> {
    let Some(start) = manifest.find("members") else {
        return Vec::new();
    };
    let rest = &manifest[start..];
    let (Some(open), Some(close)) = (rest.find('['), rest.find(']')) else {
        return Vec::new();
    };
    rest[open + 1..close]
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// The crate roots of a package's `src/`: lib.rs, main.rs, bin/*.rs,
/// bin/*/main.rs (sorted).
fn crate_roots(src: &Path) -> Vec<PathBuf> {
    let mut roots: Vec<PathBuf> = ["lib.rs", "main.rs"]
        .iter()
        .map(|f| src.join(f))
        .filter(|p| p.is_file())
        .collect();
    if let Ok(entries) = std::fs::read_dir(src.join("bin")) {
        let mut bins: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter_map(|p| {
                if p.is_file() && p.extension().is_some_and(|e| e == "rs") {
                    Some(p)
                } else if p.join("main.rs").is_file() {
                    Some(p.join("main.rs"))
                } else {
                    None
                }
            })
            .collect();
        bins.sort();
        roots.extend(bins);
    }
    roots
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn members_are_read_from_the_manifest() {
        let manifest = "[workspace]\nresolver = \"3\"\nmembers = [\"protocol\", \"hil/report\"]\nexclude = [\"x\"]\n";
        assert_eq!(workspace_members(manifest), vec!["protocol", "hil/report"]);
    }
}
