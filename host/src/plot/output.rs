//! Where a figure goes: its format from the `--out` extension (PNG or SVG,
//! the two backends of plotters the workspace builds), and the checks that
//! turn a bad path into words before anything is drawn.

use std::path::Path;

use crate::exit::{Exit, FAILURE, USAGE};

/// A figure's file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// A PNG bitmap (plotters' bitmap backend).
    Png,
    /// An SVG vector drawing (plotters' SVG backend): scales in a report.
    Svg,
}

/// The format `out` asks for by its extension (any case), and that its
/// directory exists: an unknown extension exits 2, a missing directory 1,
/// each with what to do.
pub fn format_of(out: &Path) -> Result<Format, Exit> {
    let ext = out
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let format = match ext.as_deref() {
        Some("png") => Format::Png,
        Some("svg") => Format::Svg,
        Some("pdf") => {
            return Err(Exit::new(
                USAGE,
                format!(
                    "{}: PDF is not supported (the plotting library writes PNG and SVG only); \
                     write FILE.svg and convert it, e.g. `rsvg-convert -f pdf -o FILE.pdf FILE.svg`",
                    out.display()
                ),
            ));
        }
        other => {
            return Err(Exit::new(
                USAGE,
                format!(
                    "{}: {} — name the figure FILE.png (bitmap) or FILE.svg (vector, for reports)",
                    out.display(),
                    match other {
                        Some(e) => format!("unknown figure format .{e}"),
                        None => "no file extension".to_string(),
                    }
                ),
            ));
        }
    };
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(Exit::new(
            FAILURE,
            format!(
                "cannot write {}: the directory {} does not exist (create it, or write the figure elsewhere)",
                out.display(),
                dir.display()
            ),
        ));
    }
    if out.is_dir() {
        return Err(Exit::new(
            FAILURE,
            format!("cannot write {}: it is a directory", out.display()),
        ));
    }
    Ok(format)
}

/// The words for a drawing that failed at `out` (plotters reports a file it
/// cannot create as a Debug dump): permission and missing-file errors named.
pub fn write_error(out: &Path, e: &dyn std::fmt::Debug) -> anyhow::Error {
    let raw = format!("{e:?}");
    let why = if raw.contains("PermissionDenied") || raw.contains("Permission denied") {
        "permission denied (choose a directory you can write)".to_string()
    } else if raw.contains("NotFound") || raw.contains("No such file") {
        "the directory does not exist".to_string()
    } else {
        format!("drawing failed ({raw})")
    };
    anyhow::Error::from(Exit::new(
        FAILURE,
        format!("cannot write the figure {}: {why}", out.display()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_extension_chooses_the_format_and_bad_paths_are_refused_in_words() {
        let dir = tempfile::tempdir().unwrap();
        let p = |name: &str| dir.path().join(name);
        assert_eq!(format_of(&p("a.png")).unwrap(), Format::Png);
        assert_eq!(format_of(&p("a.SVG")).unwrap(), Format::Svg);
        let e = format_of(&p("a.pdf")).unwrap_err();
        assert_eq!(e.code, USAGE);
        assert!(e.message.contains("PDF is not supported"), "{e}");
        let e = format_of(&p("a.jpg")).unwrap_err();
        assert!(
            e.message.contains(".jpg") && e.message.contains("FILE.svg"),
            "{e}"
        );
        let e = format_of(&p("noext")).unwrap_err();
        assert!(e.message.contains("no file extension"), "{e}");
        let e = format_of(&p("missing/a.png")).unwrap_err();
        assert_eq!(e.code, FAILURE);
        assert!(e.message.contains("does not exist"), "{e}");
        assert!(
            format_of(Path::new("a.png")).is_ok(),
            "the current directory"
        );
    }
}
