//! One file of the module check: its `mod` declarations, `use` trees,
//! module-level items and the paths that may reach another module.

use super::lex::{Tok, lex};

/// A module path inside the crate (`[]` is the crate root).
pub(super) type ModPath = Vec<String>;

/// A `mod name;` (or inline `mod name { … }`) declaration.
#[derive(Debug)]
pub(super) struct ModDecl {
    /// The module it is declared in.
    pub(super) scope: ModPath,
    pub(super) name: String,
    /// `#[path = "…"]`, if any.
    pub(super) path_attr: Option<String>,
    pub(super) inline: bool,
}

/// A `use` leaf: the name it binds (`*` for a glob) and its path as written.
#[derive(Debug, Clone)]
pub(super) struct UseLeaf {
    pub(super) name: String,
    pub(super) path: Vec<String>,
}

/// What one file says: its declarations, imports and path references.
#[derive(Debug, Default)]
pub(super) struct Parsed {
    pub(super) mods: Vec<ModDecl>,
    /// (scope, leaf, line, at module level: a binding others may reach)
    pub(super) uses: Vec<(ModPath, UseLeaf, u32, bool)>,
    /// Items defined at module level: (scope, name).
    pub(super) defs: Vec<(ModPath, String)>,
    /// Paths outside `use` that may reach another module: (scope, path, line).
    pub(super) refs: Vec<(ModPath, Vec<String>, u32)>,
}

const ITEM_KEYWORDS: [&str; 8] = [
    "fn", "struct", "enum", "trait", "type", "const", "static", "union",
];

/// Parse a file whose module is `module`.
pub(super) fn parse(src: &str, module: &[String]) -> Parsed {
    let toks = lex(src);
    let tok = |i: usize| toks.get(i).map(|t| &t.0);
    let ident = |i: usize| match tok(i) {
        Some(Tok::Ident(s)) => Some(s.as_str()),
        _ => None,
    };
    let mut p = Parsed::default();
    // (module path, brace depth of its items)
    let mut scopes: Vec<(ModPath, usize)> = vec![(module.to_vec(), 0)];
    let mut depth = 0usize;
    let mut path_attr: Option<String> = None;
    let mut i = 0usize;
    while i < toks.len() {
        let (t, line) = (&toks[i].0, toks[i].1);
        let scope = scopes.last().map(|s| s.0.clone()).unwrap_or_default();
        let at_item_level = scopes.last().is_some_and(|s| s.1 == depth);
        match t {
            Tok::Punct('#') if tok(i + 1) == Some(&Tok::Punct('[')) => {
                if ident(i + 2) == Some("path")
                    && tok(i + 3) == Some(&Tok::Punct('='))
                    && let Some(Tok::Str(s)) = tok(i + 4)
                {
                    path_attr = Some(s.clone());
                }
                // Skip the attribute, keeping a path attribute for its `mod`.
                let mut d = 0usize;
                i += 1;
                while i < toks.len() {
                    match toks[i].0 {
                        Tok::Punct('[') => d += 1,
                        Tok::Punct(']') => {
                            d -= 1;
                            if d == 0 {
                                break;
                            }
                        }
                        _ => {}
                    }
                    i += 1;
                }
            }
            Tok::Punct('{') => {
                depth += 1;
                path_attr = None;
            }
            Tok::Punct('}') => {
                if scopes.len() > 1 && scopes.last().is_some_and(|s| s.1 == depth) {
                    scopes.pop();
                }
                depth = depth.saturating_sub(1);
                path_attr = None;
            }
            Tok::Punct(';') => path_attr = None,
            Tok::Ident(k) if k == "mod" && ident(i + 1).is_some() => {
                let name = ident(i + 1).unwrap_or_default().to_string();
                let inline = tok(i + 2) == Some(&Tok::Punct('{'));
                p.mods.push(ModDecl {
                    scope: scope.clone(),
                    name: name.clone(),
                    path_attr: path_attr.take(),
                    inline,
                });
                if inline {
                    let mut inner = scope;
                    inner.push(name);
                    depth += 1;
                    scopes.push((inner, depth));
                    i += 2;
                }
                i += 1;
            }
            Tok::Ident(k) if k == "use" => {
                let mut j = i + 1;
                let mut leaves = Vec::new();
                use_tree(&toks, &mut j, &[], &mut leaves);
                for leaf in leaves {
                    p.uses.push((scope.clone(), leaf, line, at_item_level));
                }
                // On the `;` (consumed below); `use<'a>` in a bound is no
                // declaration: nothing more is skipped (a `{` may follow).
                i = if tok(j) == Some(&Tok::Punct(';')) {
                    j
                } else {
                    j - 1
                };
            }
            Tok::Ident(k) if ITEM_KEYWORDS.contains(&k.as_str()) && at_item_level => {
                if let Some(name) = ident(i + 1) {
                    p.defs.push((scope, name.to_string()));
                }
            }
            Tok::Ident(k) if k == "macro_rules" => {
                if let Some(name) = ident(i + 2) {
                    p.defs.push((scope, name.to_string()));
                }
            }
            Tok::Ident(first) if tok(i + 1) == Some(&Tok::PathSep) => {
                let prev = i.checked_sub(1).and_then(tok);
                let after_sep = prev == Some(&Tok::PathSep);
                // `$name::…` in a macro is a metavariable (`$crate` is the crate).
                let metavar = prev == Some(&Tok::Punct('$')) && first != "crate";
                // `pub(in crate::a)` is a visibility, not a use.
                let visibility = i >= 2
                    && prev == Some(&Tok::Ident("in".into()))
                    && tok(i - 2) == Some(&Tok::Punct('('));
                let mut path = vec![first.clone()];
                let mut j = i + 1;
                while tok(j) == Some(&Tok::PathSep) {
                    match ident(j + 1) {
                        Some(s) => path.push(s.to_string()),
                        None => break,
                    }
                    j += 2;
                }
                if !after_sep && !metavar && !visibility {
                    p.refs.push((scope, path, line));
                }
                i = j;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    p
}

/// Parse a use tree at `*j` (after `use` or inside braces), with `prefix`
/// the path so far; push its leaves. Stops before `,`, `}` or `;`.
pub(super) fn use_tree(
    toks: &[(Tok, u32)],
    j: &mut usize,
    prefix: &[String],
    out: &mut Vec<UseLeaf>,
) {
    let tok = |i: usize| toks.get(i).map(|t| &t.0);
    let mut path = prefix.to_vec();
    if tok(*j) == Some(&Tok::PathSep) {
        // `::name`: an external crate.
        path.push("::".into());
        *j += 1;
    }
    loop {
        match tok(*j) {
            Some(Tok::Ident(s)) => {
                path.push(s.clone());
                *j += 1;
                if tok(*j) == Some(&Tok::PathSep) {
                    *j += 1;
                    continue;
                }
                let mut name = s.clone();
                if tok(*j) == Some(&Tok::Ident("as".into())) {
                    if let Some(Tok::Ident(alias)) = tok(*j + 1) {
                        name = alias.clone();
                    }
                    *j += 2;
                }
                if name == "self" {
                    // `a::{self}`: the module itself.
                    path.pop();
                    name = path.last().cloned().unwrap_or_default();
                }
                out.push(UseLeaf { name, path });
                return;
            }
            Some(Tok::Punct('*')) => {
                *j += 1;
                out.push(UseLeaf {
                    name: "*".into(),
                    path,
                });
                return;
            }
            Some(Tok::Punct('{')) => {
                *j += 1;
                while let Some(t) = tok(*j) {
                    match t {
                        Tok::Punct('}') => {
                            *j += 1;
                            break;
                        }
                        Tok::Punct(',') => *j += 1,
                        _ => {
                            let before = *j;
                            use_tree(toks, j, &path, out);
                            if *j == before {
                                *j += 1; // not a tree: skip the token
                            }
                        }
                    }
                }
                return;
            }
            _ => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn use_trees_give_each_leaf_its_name_and_path() {
        let mut leaves = Vec::new();
        let toks = lex("{std::io, crate::a::{self, g as h}, ::ext::x}");
        use_tree(&toks, &mut 0, &[], &mut leaves);
        let got: Vec<(String, String)> = leaves
            .iter()
            .map(|l| (l.name.clone(), l.path.join("::")))
            .collect();
        assert_eq!(
            got,
            vec![
                ("io".into(), "std::io".into()),
                ("a".into(), "crate::a".into()),
                ("h".into(), "crate::a::g".into()),
                ("x".into(), "::::ext::x".into()),
            ]
        );
    }
}
