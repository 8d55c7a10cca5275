//! One crate of the module check: its module tree walked from the root
//! file, each path resolved to the file that defines its item, the
//! file-level import graph and its circles.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

use super::parse::{ModPath, Parsed, parse};

/// What a module holds, for resolving names in it.
#[derive(Debug, Default)]
struct Module {
    file: usize,
    defs: BTreeSet<String>,
    children: BTreeSet<String>,
    /// Named imports: bound name → path as written.
    bindings: BTreeMap<String, Vec<String>>,
    /// Glob imports: paths as written.
    globs: Vec<Vec<String>>,
}

/// A crate's files and the imports between them.
#[derive(Debug, Default)]
pub(super) struct Graph {
    /// Repository-relative file names.
    pub(super) files: Vec<String>,
    modules: HashMap<ModPath, Module>,
    /// from → to → (line, path) of the first import found.
    pub(super) edges: BTreeMap<usize, BTreeMap<usize, (u32, String)>>,
}

/// Resolution gives up after this many re-export hops (a loop of globs).
const MAX_HOPS: usize = 16;

impl Graph {
    /// Walk the module tree of `crate_root` and build its import graph.
    pub(super) fn load(root: &Path, crate_root: &Path) -> Result<Graph> {
        let mut sources = Vec::new();
        let mut queue = vec![(crate_root.to_path_buf(), ModPath::new(), true)];
        while let Some((file, module, mod_rs)) = queue.pop() {
            let src = std::fs::read_to_string(&file)
                .with_context(|| format!("reading {}", file.display()))?;
            let name = file
                .strip_prefix(root)
                .unwrap_or(&file)
                .to_string_lossy()
                .into_owned();
            let parsed = parse(&src, &module);
            let dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
            for decl in parsed.mods.iter().filter(|d| !d.inline) {
                // The directory of the declaring scope: the file's own
                // (mod.rs, lib.rs, main.rs, #[path] files) or the one named
                // after it, then one directory per inline module.
                let mut base = if mod_rs {
                    dir.clone()
                } else {
                    dir.join(file.file_stem().unwrap_or_default())
                };
                for inline in &decl.scope[module.len()..] {
                    base.push(inline);
                }
                let mut child = module.clone();
                child.extend_from_slice(&decl.scope[module.len()..]);
                child.push(decl.name.clone());
                let (path, child_mod_rs) = match &decl.path_attr {
                    Some(p) => (base.join(p), true),
                    None => {
                        let flat = base.join(format!("{}.rs", decl.name));
                        if flat.is_file() {
                            (flat, false)
                        } else {
                            (base.join(&decl.name).join("mod.rs"), true)
                        }
                    }
                };
                queue.push((path, child, child_mod_rs));
            }
            sources.push((name, module, parsed));
        }
        Ok(Graph::build(sources))
    }

    /// The graph of parsed files: (file name, module path, parsed).
    fn build(sources: Vec<(String, ModPath, Parsed)>) -> Graph {
        let mut g = Graph::default();
        for (index, (name, module, parsed)) in sources.iter().enumerate() {
            g.files.push(name.clone());
            g.modules.entry(module.clone()).or_default().file = index;
            for decl in &parsed.mods {
                let mut child = decl.scope.clone();
                child.push(decl.name.clone());
                if decl.inline {
                    g.modules.entry(child).or_default().file = index;
                }
                g.modules
                    .entry(decl.scope.clone())
                    .or_default()
                    .children
                    .insert(decl.name.clone());
            }
            for (scope, name) in &parsed.defs {
                g.modules
                    .entry(scope.clone())
                    .or_default()
                    .defs
                    .insert(name.clone());
            }
            for (scope, leaf, _, item_level) in &parsed.uses {
                let m = g.modules.entry(scope.clone()).or_default();
                if leaf.name == "*" {
                    m.globs.push(leaf.path.clone());
                } else if *item_level && leaf.name != "_" {
                    m.bindings
                        .entry(leaf.name.clone())
                        .or_insert(leaf.path.clone());
                }
            }
        }
        for (index, (_, _, parsed)) in sources.iter().enumerate() {
            let uses = parsed
                .uses
                .iter()
                .map(|(s, l, line, _)| (s, &l.path, *line));
            let refs = parsed.refs.iter().map(|(s, p, line)| (s, p, *line));
            for (scope, path, line) in uses.chain(refs) {
                let Some(abs) = g.absolute(scope, path, 0) else {
                    continue;
                };
                if let Some(to) = g.target(&abs, 0)
                    && to != index
                {
                    g.edges
                        .entry(index)
                        .or_default()
                        .entry(to)
                        .or_insert((line, path.join("::")));
                }
            }
        }
        g
    }

    /// `path` as written in `scope`, as a path from the crate root; `None`
    /// when it leaves the crate (std, another crate) or cannot be resolved.
    fn absolute(&self, scope: &[String], path: &[String], hops: usize) -> Option<ModPath> {
        if hops > MAX_HOPS {
            return None;
        }
        let first = path.first()?;
        let mut rest = &path[1..];
        let mut base: ModPath = match first.as_str() {
            "crate" => Vec::new(),
            "self" => scope.to_vec(),
            "super" => {
                let mut b = scope.to_vec();
                b.pop()?;
                while rest.first().is_some_and(|s| s == "super") {
                    b.pop()?;
                    rest = &rest[1..];
                }
                b
            }
            "::" => return None,
            name => {
                // A name in scope: a child module, an item, an import.
                let m = self.modules.get(scope)?;
                if m.children.contains(name) || m.defs.contains(name) {
                    let mut b = scope.to_vec();
                    b.push(name.to_string());
                    b
                } else if let Some(bound) = m.bindings.get(name) {
                    if hops >= MAX_HOPS || bound.first().is_some_and(|f| f == name) {
                        return None; // `use name;` of an external crate
                    }
                    self.absolute(scope, bound, hops + 1)?
                } else {
                    // Through a glob import (`use super::*` in a tests file).
                    return m.globs.iter().find_map(|glob| {
                        let source = self.absolute(scope, glob, hops + 1)?;
                        let s = self.modules.get(&source)?;
                        let known = s.children.contains(name)
                            || s.defs.contains(name)
                            || s.bindings.contains_key(name);
                        if !known || hops >= MAX_HOPS || source.as_slice() == scope {
                            return None;
                        }
                        self.absolute(&source, path, hops + 1)
                    });
                }
            }
        };
        base.extend_from_slice(rest);
        Some(base)
    }

    /// The file that defines the item (or module) at `abs`.
    fn target(&self, abs: &[String], hops: usize) -> Option<usize> {
        let split = (0..=abs.len())
            .rev()
            .find(|&k| self.modules.contains_key(&abs[..k]))?;
        let (module_path, rest) = abs.split_at(split);
        let module = self.modules.get(module_path)?;
        let Some(name) = rest.first() else {
            return Some(module.file);
        };
        if module.defs.contains(name) || hops >= MAX_HOPS {
            return Some(module.file);
        }
        if let Some(bound) = module.bindings.get(name) {
            // A re-export: the item lives where the import points
            // (nowhere in the crate: an external item, no edge).
            let mut to = self.absolute(module_path, bound, hops + 1)?;
            to.extend_from_slice(&rest[1..]);
            return self.target(&to, hops + 1);
        }
        for glob in &module.globs {
            let Some(source) = self.absolute(module_path, glob, hops + 1) else {
                continue;
            };
            if source.as_slice() == module_path {
                continue;
            }
            let Some(m) = self.modules.get(&source) else {
                continue;
            };
            if m.defs.contains(name) || m.bindings.contains_key(name) || m.children.contains(name) {
                let mut to = source;
                to.extend_from_slice(rest);
                return self.target(&to, hops + 1);
            }
        }
        Some(module.file)
    }

    /// Every circle: the strongly connected components of more than one
    /// file (Tarjan), each sorted by file name, in file-name order.
    pub(super) fn circles(&self) -> Vec<Vec<usize>> {
        struct State<'a> {
            g: &'a Graph,
            index: Vec<Option<usize>>,
            low: Vec<usize>,
            on_stack: Vec<bool>,
            stack: Vec<usize>,
            next: usize,
            out: Vec<Vec<usize>>,
        }
        fn visit(s: &mut State, v: usize) {
            s.index[v] = Some(s.next);
            s.low[v] = s.next;
            s.next += 1;
            s.stack.push(v);
            s.on_stack[v] = true;
            let succ: Vec<usize> =
                s.g.edges
                    .get(&v)
                    .map(|e| e.keys().copied().collect())
                    .unwrap_or_default();
            for w in succ {
                match s.index[w] {
                    None => {
                        visit(s, w);
                        s.low[v] = s.low[v].min(s.low[w]);
                    }
                    Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                    Some(_) => {}
                }
            }
            if Some(s.low[v]) == s.index[v] {
                let mut component = Vec::new();
                while let Some(w) = s.stack.pop() {
                    s.on_stack[w] = false;
                    component.push(w);
                    if w == v {
                        break;
                    }
                }
                if component.len() > 1 {
                    s.out.push(component);
                }
            }
        }
        let n = self.files.len();
        let mut s = State {
            g: self,
            index: vec![None; n],
            low: vec![0; n],
            on_stack: vec![false; n],
            stack: Vec::new(),
            next: 0,
            out: Vec::new(),
        };
        for v in 0..n {
            if s.index[v].is_none() {
                visit(&mut s, v);
            }
        }
        for c in &mut s.out {
            c.sort_by(|&a, &b| self.files[a].cmp(&self.files[b]));
        }
        s.out
            .sort_by(|a, b| self.files[a[0]].cmp(&self.files[b[0]]));
        s.out
    }

    /// Every file and the files it imports, one line each.
    pub(super) fn listing(&self) -> String {
        let mut text = String::new();
        for (from, name) in self.files.iter().enumerate() {
            let to: Vec<&str> = self
                .edges
                .get(&from)
                .into_iter()
                .flat_map(BTreeMap::keys)
                .map(|&t| self.files[t].as_str())
                .collect();
            let _ = writeln!(text, "{name} -> {}", to.join(", "));
        }
        text
    }

    /// A circle's files and the imports between them.
    pub(super) fn describe(&self, circle: &[usize]) -> String {
        let names: Vec<&str> = circle.iter().map(|&f| self.files[f].as_str()).collect();
        let mut text = format!("  circle: {}\n", names.join(", "));
        for &from in circle {
            for (to, (line, path)) in self.edges.get(&from).into_iter().flatten() {
                if circle.contains(to) {
                    let _ = writeln!(
                        text,
                        "    {}:{line} uses {path} ({})",
                        self.files[from], self.files[*to]
                    );
                }
            }
        }
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The graph of in-memory files: (file name, module path, source).
    fn graph(files: &[(&str, &[&str], &str)]) -> Graph {
        let sources = files
            .iter()
            .map(|(name, module, src)| {
                let module: ModPath = module.iter().map(|s| s.to_string()).collect();
                let parsed = parse(src, &module);
                (name.to_string(), module, parsed)
            })
            .collect();
        Graph::build(sources)
    }

    fn circle_names(g: &Graph) -> Vec<Vec<&str>> {
        g.circles()
            .iter()
            .map(|c| c.iter().map(|&f| g.files[f].as_str()).collect())
            .collect()
    }

    fn edge_names(g: &Graph) -> Vec<(&str, &str)> {
        let mut out = Vec::new();
        for (from, tos) in &g.edges {
            for to in tos.keys() {
                out.push((g.files[*from].as_str(), g.files[*to].as_str()));
            }
        }
        out
    }

    #[test]
    fn a_loop_of_three_files_is_one_circle() {
        let g = graph(&[
            ("lib.rs", &[], "mod a;\nmod b;\nmod c;\nmod d;\n"),
            ("a.rs", &["a"], "use crate::b::B;\npub struct A;\n"),
            ("b.rs", &["b"], "pub struct B(crate::c::C);\n"),
            (
                "c.rs",
                &["c"],
                "pub fn f() -> super::a::A { todo!() }\npub struct C;\n",
            ),
            ("d.rs", &["d"], "use crate::a::A;\n"),
        ]);
        assert_eq!(circle_names(&g), vec![vec!["a.rs", "b.rs", "c.rs"]]);
        let text = g.describe(&g.circles()[0]);
        assert!(text.contains("a.rs:1 uses crate::b::B (b.rs)"), "{text}");
        assert!(text.contains("c.rs:1 uses super::a::A (a.rs)"), "{text}");
    }

    #[test]
    fn a_tree_has_no_circle() {
        let g = graph(&[
            ("lib.rs", &[], "mod a;\nmod b;\npub use a::A;\n"),
            (
                "a.rs",
                &["a"],
                "use crate::b::{self, B};\npub struct A(B);\n",
            ),
            ("b.rs", &["b"], "pub struct B;\n"),
        ]);
        assert!(g.circles().is_empty());
        assert_eq!(edge_names(&g), vec![("lib.rs", "a.rs"), ("a.rs", "b.rs")]);
    }

    #[test]
    fn super_and_crate_resolve_to_the_defining_file() {
        // a/mod.rs declares b and c; a/b.rs reaches c through super and
        // crate, and the crate root's re-export through crate::.
        let g = graph(&[
            ("lib.rs", &[], "mod a;\nmod x;\npub use x::X;\n"),
            ("a/mod.rs", &["a"], "mod b;\nmod c;\n"),
            (
                "a/b.rs",
                &["a", "b"],
                "use super::c::C;\nfn f() { let _ = crate::a::c::new(); let _: crate::X; }\n",
            ),
            ("a/c.rs", &["a", "c"], "pub struct C;\npub fn new() {}\n"),
            ("x.rs", &["x"], "pub struct X;\n"),
        ]);
        assert!(g.circles().is_empty());
        assert_eq!(
            edge_names(&g),
            vec![("lib.rs", "x.rs"), ("a/b.rs", "a/c.rs"), ("a/b.rs", "x.rs")]
        );
    }

    #[test]
    fn an_inline_tests_module_using_super_is_no_circle() {
        let g = graph(&[
            ("lib.rs", &[], "mod run;\n"),
            (
                "run.rs",
                &["run"],
                "pub fn run() {}\n#[cfg(test)]\nmod tests {\n    use super::*;\n    use super::super::run::run as r;\n    #[test]\n    fn t() { super::run(); }\n}\npub fn after() {}\n",
            ),
        ]);
        assert!(g.edges.is_empty(), "{:?}", g.edges);
        // The scope closes with the block: `after` is run's.
        assert!(g.modules[&vec!["run".to_string()]].defs.contains("after"));
    }

    #[test]
    fn parent_and_child_importing_each_other_is_a_circle_but_a_mod_declaration_is_not() {
        let declared_only = graph(&[
            ("lib.rs", &[], "mod a;\n"),
            ("a/mod.rs", &["a"], "mod b;\npub struct P;\n"),
            ("a/b.rs", &["a", "b"], "use super::P;\n"),
        ]);
        assert!(declared_only.circles().is_empty());
        let both = graph(&[
            ("lib.rs", &[], "mod a;\n"),
            ("a/mod.rs", &["a"], "mod b;\nuse b::Q;\npub struct P;\n"),
            ("a/b.rs", &["a", "b"], "use super::P;\npub struct Q;\n"),
        ]);
        assert_eq!(circle_names(&both), vec![vec!["a/b.rs", "a/mod.rs"]]);
    }

    #[test]
    fn comments_strings_and_chars_are_not_imports() {
        let g = graph(&[
            ("lib.rs", &[], "mod a;\nmod b;\n"),
            (
                "a.rs",
                &["a"],
                "/// See [`crate::b::B`].\n// use crate::b::B;\n/* crate::b::B /* nested */ crate::b::B */\n\
                 const S: &str = \"crate::b::B\";\nconst R: &str = r#\"use crate::b::B;\"#;\n\
                 const C: char = '\"'; const Q: char = '\\''; fn f<'a>(x: &'a str) -> &'a str { x }\n\
                 pub struct A;\n",
            ),
            ("b.rs", &["b"], "use crate::a::A;\npub struct B;\n"),
        ]);
        assert!(g.circles().is_empty());
        assert_eq!(edge_names(&g), vec![("b.rs", "a.rs")]);
    }

    #[test]
    fn use_trees_globs_and_child_names_resolve() {
        let g = graph(&[
            ("main.rs", &[], "mod a;\nmod b;\nfn main() { a::run(); }\n"),
            ("a.rs", &["a"], "pub use crate::b::*;\npub fn run() {}\n"),
            ("b.rs", &["b"], "pub fn g() {}\n"),
        ]);
        assert_eq!(edge_names(&g), vec![("main.rs", "a.rs"), ("a.rs", "b.rs")]);
        // A glob re-export: `crate::a::g` is b's.
        let abs = g.absolute(&[], &["crate".into(), "a".into(), "g".into()], 0);
        assert_eq!(abs.as_deref().and_then(|p| g.target(p, 0)), Some(2));
    }

    #[test]
    fn the_tree_is_walked_through_files_dirs_and_path_attributes() {
        let dir = std::env::temp_dir().join(format!("xtask-modules-{}", std::process::id()));
        let files = [
            (
                "src/lib.rs",
                "mod a;\nmod b;\n#[path = \"other/c_impl.rs\"]\nmod c;\n",
            ),
            // a.rs is not a mod-rs file: its child lives in a/.
            ("src/a.rs", "mod inner;\npub use inner::I;\n"),
            ("src/a/inner.rs", "use crate::b::B;\npub struct I;\n"),
            ("src/b/mod.rs", "mod deep;\npub struct B;\n"),
            ("src/b/deep.rs", "use crate::c::C;\n"),
            ("src/other/c_impl.rs", "pub struct C;\n"),
        ];
        for (name, text) in files {
            let path = dir.join(name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, text).unwrap();
        }
        let g = Graph::load(&dir, &dir.join("src/lib.rs"));
        std::fs::remove_dir_all(&dir).unwrap();
        let g = g.unwrap();
        let mut names = g.files.clone();
        names.sort();
        assert_eq!(
            names,
            [
                "src/a.rs",
                "src/a/inner.rs",
                "src/b/deep.rs",
                "src/b/mod.rs",
                "src/lib.rs",
                "src/other/c_impl.rs"
            ]
        );
        let mut edges = edge_names(&g);
        edges.sort();
        assert_eq!(
            edges,
            [
                ("src/a.rs", "src/a/inner.rs"),
                ("src/a/inner.rs", "src/b/mod.rs"),
                ("src/b/deep.rs", "src/other/c_impl.rs"),
            ]
        );
    }

    #[test]
    fn a_use_bound_and_a_tests_file_glob_are_read_right() {
        let g = graph(&[
            ("lib.rs", &[], "mod a;\nmod b;\n"),
            (
                "a/mod.rs",
                &["a"],
                "fn f<'a>(x: &'a [u8]) -> impl Iterator<Item = &'a u8> + use<'a> { x.iter() }\n\
                 mod inner { pub fn g() {} }\npub fn after() {}\nuse crate::b;\n#[cfg(test)]\nmod tests;\n",
            ),
            (
                "a/tests.rs",
                &["a", "tests"],
                "use super::*;\nfn t() { b::deep::h(); }\n",
            ),
            ("b/mod.rs", &["b"], "pub mod deep;\n"),
            ("b/deep.rs", &["b", "deep"], "pub fn h() {}\n"),
        ]);
        let a = &g.modules[&vec!["a".to_string()]];
        assert!(a.defs.contains("after") && a.children.contains("inner"));
        assert_eq!(
            edge_names(&g),
            vec![
                ("a/mod.rs", "b/mod.rs"),
                ("a/tests.rs", "a/mod.rs"),
                ("a/tests.rs", "b/deep.rs")
            ]
        );
    }

    #[test]
    fn globs_that_import_each_other_end() {
        // Relative globs in a loop, and a name found nowhere: no edge, no hang.
        let g = graph(&[
            ("lib.rs", &[], "mod a;\nmod b;\n"),
            (
                "a.rs",
                &["a"],
                "use x::*;\nuse crate::b::*;\nfn f() { nowhere::g(); }\n",
            ),
            ("b.rs", &["b"], "use y::*;\nuse crate::a::*;\n"),
        ]);
        assert_eq!(edge_names(&g), vec![("a.rs", "b.rs"), ("b.rs", "a.rs")]);
    }
}
