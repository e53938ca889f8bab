//! HTML reports: a page builder that collects headings, text, tables and
//! figures, and writes `DIR/index.html` plus every figure as `DIR/<name>.svg`.
//!
//! The page is self-contained: the SVGs are inlined (a copy of each is also
//! written beside it for use elsewhere), the style sheet is embedded, and
//! there are no scripts, fonts or links to fetch — it opens in a browser on
//! an offline shop-floor PC and can be mailed as one file. All text is HTML-
//! escaped here, so callers pass plain strings (file names, metadata from a
//! CSV) without thinking about markup.
//!
//! The plots themselves are in [`plot`]; `compare`, `diagnose`, `iso230` and
//! `history` build pages from the same pieces.

pub mod compare;
pub mod diagnose;
pub mod history;
pub mod iso230;
pub mod plot;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

/// One block of a page, in display order.
#[derive(Clone, Debug)]
enum Block {
    Heading(u8, String),
    Paragraph(String),
    Pre(String),
    Table {
        header: Vec<String>,
        rows: Vec<Vec<String>>,
    },
    Figure {
        name: String,
        caption: String,
        svg: String,
    },
}

/// An HTML report under construction.
#[derive(Clone, Debug)]
pub struct Page {
    title: String,
    blocks: Vec<Block>,
}

impl Page {
    /// A page with a title (shown as the top heading and the window title).
    pub fn new(title: impl Into<String>) -> Page {
        Page {
            title: title.into(),
            blocks: Vec::new(),
        }
    }

    /// A section heading (level 2).
    pub fn heading(&mut self, text: impl Into<String>) -> &mut Page {
        self.blocks.push(Block::Heading(2, text.into()));
        self
    }

    /// A sub-section heading (level 3).
    pub fn subheading(&mut self, text: impl Into<String>) -> &mut Page {
        self.blocks.push(Block::Heading(3, text.into()));
        self
    }

    /// A paragraph of plain text.
    pub fn paragraph(&mut self, text: impl Into<String>) -> &mut Page {
        self.blocks.push(Block::Paragraph(text.into()));
        self
    }

    /// Preformatted text (a command line, a file excerpt).
    pub fn preformatted(&mut self, text: impl Into<String>) -> &mut Page {
        self.blocks.push(Block::Pre(text.into()));
        self
    }

    /// A table with a header row.
    pub fn table(&mut self, header: &[&str], rows: Vec<Vec<String>>) -> &mut Page {
        self.blocks.push(Block::Table {
            header: header.iter().map(|s| s.to_string()).collect(),
            rows,
        });
        self
    }

    /// A figure: `svg` (from [`plot`]) inlined in the page and also written
    /// as `<name>.svg`. `name` must be a plain file stem (letters, digits,
    /// `-`, `_`) and unique on the page.
    pub fn figure(
        &mut self,
        name: impl Into<String>,
        caption: impl Into<String>,
        svg: String,
    ) -> &mut Page {
        self.blocks.push(Block::Figure {
            name: name.into(),
            caption: caption.into(),
            svg,
        });
        self
    }

    /// Number of figures on the page.
    pub fn figure_count(&self) -> usize {
        self.blocks
            .iter()
            .filter(|b| matches!(b, Block::Figure { .. }))
            .count()
    }

    /// The whole page as one HTML document.
    pub fn to_html(&self) -> String {
        let mut h = String::new();
        let _ = write!(
            h,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
            esc(&self.title),
            STYLE,
            esc(&self.title)
        );
        for b in &self.blocks {
            match b {
                Block::Heading(level, t) => {
                    let _ = writeln!(h, "<h{level}>{}</h{level}>", esc(t));
                }
                Block::Paragraph(t) => {
                    let _ = writeln!(h, "<p>{}</p>", esc(t));
                }
                Block::Pre(t) => {
                    let _ = writeln!(h, "<pre>{}</pre>", esc(t));
                }
                Block::Table { header, rows } => {
                    h.push_str("<table>\n<thead><tr>");
                    for c in header {
                        let _ = write!(h, "<th>{}</th>", esc(c));
                    }
                    h.push_str("</tr></thead>\n<tbody>\n");
                    for r in rows {
                        h.push_str("<tr>");
                        for c in r {
                            let _ = write!(h, "<td>{}</td>", esc(c));
                        }
                        h.push_str("</tr>\n");
                    }
                    h.push_str("</tbody>\n</table>\n");
                }
                Block::Figure { name, caption, svg } => {
                    let _ = write!(
                        h,
                        "<figure id=\"{}\">\n{}\n<figcaption>{} <a href=\"{}.svg\">(SVG)</a></figcaption>\n</figure>\n",
                        esc(name),
                        strip_xml_declaration(svg),
                        esc(caption),
                        esc(name)
                    );
                }
            }
        }
        h.push_str("</body>\n</html>\n");
        h
    }

    /// Writes `dir/index.html` and `dir/<name>.svg` for every figure
    /// (creating `dir`); returns the path of index.html.
    pub fn write(&self, dir: &Path) -> Result<PathBuf> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the report directory {}", dir.display()))?;
        let mut names: Vec<&str> = Vec::new();
        for b in &self.blocks {
            if let Block::Figure { name, svg, .. } = b {
                if name.is_empty()
                    || !name
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
                {
                    bail!("figure name `{name}` is not a plain file stem");
                }
                if names.contains(&name.as_str()) {
                    bail!("figure name `{name}` used twice on one page");
                }
                names.push(name);
                let path = dir.join(format!("{name}.svg"));
                std::fs::write(&path, svg)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
        }
        let index = dir.join("index.html");
        std::fs::write(&index, self.to_html())
            .with_context(|| format!("writing {}", index.display()))?;
        Ok(index)
    }
}

/// HTML-escapes text for element content and attribute values.
pub fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// An inline `<svg>` inside HTML must not carry an XML declaration.
fn strip_xml_declaration(svg: &str) -> &str {
    let t = svg.trim_start();
    if t.starts_with("<?xml") {
        t.find("?>").map_or(t, |i| t[i + 2..].trim_start())
    } else {
        t
    }
}

/// Print-friendly, dependency-free styling.
const STYLE: &str = "body{font-family:sans-serif;max-width:1500px;margin:1em auto;padding:0 1em;color:#222}\
h1{font-size:1.5em}h2{font-size:1.25em;border-bottom:1px solid #ccc;margin-top:1.6em}\
h3{font-size:1.05em}table{border-collapse:collapse;margin:.6em 0}\
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right;font-variant-numeric:tabular-nums}\
th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}\
figure{display:inline-block;margin:.6em .6em .6em 0;vertical-align:top}\
figcaption{font-size:.9em;color:#555;max-width:720px}pre{background:#f6f6f6;padding:.6em;overflow-x:auto}";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_escapes_and_inlines() {
        let mut p = Page::new("compare <data.csv>");
        p.heading("Per target")
            .paragraph("a & b")
            .table(
                &["target", "RMS (µm)"],
                vec![vec!["ex".into(), "1.00".into()]],
            )
            .figure(
                "fig_1",
                "caption",
                "<?xml version=\"1.0\"?>\n<svg width=\"1\"></svg>".into(),
            );
        let html = p.to_html();
        assert!(html.contains("compare &lt;data.csv&gt;"));
        assert!(html.contains("a &amp; b"));
        assert!(html.contains("<svg width=\"1\"></svg>"));
        assert!(!html.contains("<?xml"));
        assert!(!html.contains("<script"));
        assert_eq!(p.figure_count(), 1);
    }

    #[test]
    fn write_rejects_bad_names() {
        let dir = std::env::temp_dir().join(format!("trueaxis-page-{}", std::process::id()));
        let mut p = Page::new("t");
        p.figure("../evil", "c", "<svg></svg>".into());
        assert!(p.write(&dir).is_err());
        let mut p = Page::new("t");
        p.figure("a", "c", "<svg></svg>".into())
            .figure("a", "c", "<svg></svg>".into());
        assert!(p.write(&dir).is_err());
        let mut p = Page::new("t");
        p.figure("a", "c", "<svg></svg>".into());
        let index = p.write(&dir).unwrap();
        assert!(index.ends_with("index.html"));
        assert!(dir.join("a.svg").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
