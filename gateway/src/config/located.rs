//! Where in the config file a bad value is: the line (and column) and the
//! key, from the toml crate's spans — of its own error, or of the key a
//! check names ([`KeyError`]) looked up in the parsed document
//! ([`toml::de::DeTable`]). The message never quotes the line itself (it
//! may hold a password).

use std::ops::Range;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// A bad value of the config file's key `key` (dotted, `node[2].name` for
/// the third `[[node]]`); the file's line is added when it is known.
#[derive(Debug)]
pub struct KeyError {
    /// The key, dotted.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

impl KeyError {
    /// The error of `key`.
    pub fn at(key: impl Into<String>, message: impl Into<String>) -> anyhow::Error {
        anyhow::Error::new(KeyError {
            key: key.into(),
            message: message.into(),
        })
    }
}

impl std::fmt::Display for KeyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for KeyError {}

/// The text of a config file, kept to name the line of a bad value; its
/// `Debug` does not show it (it may hold the password).
#[derive(Clone, Default)]
pub struct Source(pub String);

impl std::fmt::Debug for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Source({} bytes)", self.0.len())
    }
}

/// Line and column (1-based) of byte `at` of `text`.
fn line_col(text: &str, at: usize) -> (usize, usize) {
    let before = text.get(..at.min(text.len())).unwrap_or("");
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// The dotted key whose key or value holds `span` (the innermost), walking
/// the parsed document.
fn key_at(doc: &DeTable<'_>, span: &Range<usize>) -> Option<String> {
    fn walk(table: &DeTable<'_>, span: &Range<usize>, prefix: &str, best: &mut Option<String>) {
        for (k, v) in table {
            let path = if prefix.is_empty() {
                k.get_ref().to_string()
            } else {
                format!("{prefix}.{}", k.get_ref())
            };
            let holds =
                |s: Range<usize>| s.start <= span.start && span.end <= s.end.max(s.start + 1);
            if holds(k.span()) || holds(v.span()) {
                *best = Some(path.clone());
            }
            walk_value(v, span, &path, best);
        }
    }
    fn walk_value(
        v: &Spanned<DeValue<'_>>,
        span: &Range<usize>,
        path: &str,
        best: &mut Option<String>,
    ) {
        match v.get_ref() {
            DeValue::Table(t) => walk(t, span, path, best),
            DeValue::Array(items) => {
                for (k, item) in items.iter().enumerate() {
                    walk_value(item, span, &format!("{path}[{k}]"), best);
                }
            }
            _ => {}
        }
    }
    let mut best = None;
    walk(doc, span, "", &mut best);
    best
}

/// The span of the value of dotted `key` (`node[2].name`).
fn value_of(doc: &DeTable<'_>, key: &str) -> Option<Range<usize>> {
    let mut table = doc;
    let mut parts = key.split('.').peekable();
    while let Some(part) = parts.next() {
        let (name, index) = match part.split_once('[') {
            Some((n, i)) => (n, i.trim_end_matches(']').parse::<usize>().ok()),
            None => (part, None),
        };
        let mut v = table.iter().find(|(k, _)| k.get_ref() == name)?.1;
        if let Some(i) = index {
            let DeValue::Array(items) = v.get_ref() else {
                return None;
            };
            v = items.get(i)?;
        }
        if parts.peek().is_none() {
            return Some(v.span());
        }
        let DeValue::Table(t) = v.get_ref() else {
            return None;
        };
        table = t;
    }
    None
}

/// Every key of the document: (dotted path, span of the key).
fn keys(doc: &DeTable<'_>) -> Vec<(String, Range<usize>)> {
    fn walk(table: &DeTable<'_>, prefix: &str, out: &mut Vec<(String, Range<usize>)>) {
        for (k, v) in table {
            let path = if prefix.is_empty() {
                k.get_ref().to_string()
            } else {
                format!("{prefix}.{}", k.get_ref())
            };
            out.push((path.clone(), k.span()));
            match v.get_ref() {
                DeValue::Table(t) => walk(t, &path, out),
                DeValue::Array(items) => {
                    for (i, item) in items.iter().enumerate() {
                        if let DeValue::Table(t) = item.get_ref() {
                            walk(t, &format!("{path}[{i}]"), out);
                        }
                    }
                }
                _ => {}
            }
        }
    }
    let mut out = Vec::new();
    walk(doc, "", &mut out);
    out
}

/// A parse error of `text` with its line, column and key. A duplicate key
/// is named after its first occurrence (the one the document keeps).
pub fn parse_error(text: &str, e: &toml::de::Error) -> anyhow::Error {
    let message = e.message().trim_end();
    let Some(span) = e.span() else {
        return anyhow::anyhow!("{message}");
    };
    let (line, col) = line_col(text, span.start);
    let (doc, _) = DeTable::parse_recoverable(text);
    if let Some(k) = key_at(doc.get_ref(), &span) {
        return anyhow::anyhow!("line {line}, column {col}, key `{k}`: {message}");
    }
    // Not in the document (a duplicate): the same name before it.
    let name = text
        .get(span.clone())
        .unwrap_or("")
        .trim()
        .trim_matches('"');
    let first = keys(doc.get_ref())
        .into_iter()
        .filter(|(p, s)| s.end <= span.start && p.rsplit('.').next() == Some(name))
        .max_by_key(|(_, s)| s.start);
    match first {
        Some((k, s)) => anyhow::anyhow!(
            "line {line}, column {col}, key `{k}`: {message} (first at line {})",
            line_col(text, s.start).0
        ),
        None => anyhow::anyhow!("line {line}, column {col}: {message}"),
    }
}

/// `e` with the line of the key it names in `text`, when it names one
/// that the file has.
pub fn at_key(text: Option<&str>, e: anyhow::Error) -> anyhow::Error {
    let (Some(text), Some(k)) = (text, e.downcast_ref::<KeyError>()) else {
        return e;
    };
    let span = DeTable::parse(text)
        .ok()
        .and_then(|doc| value_of(doc.get_ref(), &k.key));
    match span {
        Some(s) => {
            let (line, _) = line_col(text, s.start);
            anyhow::anyhow!("line {line}, key `{}`: {}", k.key, k.message)
        }
        None => e,
    }
}
