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
pub mod onmachine;
pub mod plot;
pub mod volumetric;

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
    Figure(Figure),
    /// Figures side by side, as many per row as the window holds (small
    /// multiples: the planes of one target on one colour scale).
    Grid(Vec<Figure>, GridKind),
    /// The page's colour key: each target's and direction's colour, the
    /// same on every plot of every page.
    Key,
}

/// How wide the cells of a grid of figures are at least.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum GridKind {
    /// 340 px: heat maps of planes (three per row at 1280 px).
    Small,
    /// 560 px: x–y plots whose text must stay readable (two per row).
    Wide,
}

/// One figure: an SVG with a caption, written as `<name>.svg`.
#[derive(Clone, Debug)]
pub struct Figure {
    /// File stem (letters, digits, `-`, `_`), unique on the page.
    pub name: String,
    /// Caption under the figure.
    pub caption: String,
    /// The SVG document.
    pub svg: String,
    /// The same plot drawn for a phone ([`plot::Drawing::phone_svg`]),
    /// shown instead of `svg` in a window narrower than 600 px.
    pub narrow: Option<String>,
}

impl Figure {
    /// A figure of a drawn SVG (no phone drawing: it scales).
    pub fn new(name: impl Into<String>, caption: impl Into<String>, svg: String) -> Figure {
        Figure {
            name: name.into(),
            caption: caption.into(),
            svg,
            narrow: None,
        }
    }

    /// A figure of `plot`, drawn at its size and, when that is wider than
    /// a phone, again at the phone's width.
    pub fn plot(
        name: impl Into<String>,
        caption: impl Into<String>,
        plot: &dyn plot::Drawing,
    ) -> anyhow::Result<Figure> {
        Ok(Figure {
            narrow: plot.phone_svg()?,
            ..Figure::new(name, caption, plot.svg()?)
        })
    }
}

/// How a verdict reads at a glance (the card's colour).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tone {
    /// Nothing is left to do: at the noise floor.
    Good,
    /// Something is missing or left; the card says what.
    Action,
    /// Not enough to say (no noise floor, a warning undermines it).
    Unknown,
}

/// The verdict card every report opens with: the answer in words, the
/// warnings that undermine it, and the one command to run next.
#[derive(Clone, Debug)]
pub struct Verdict {
    /// The answer in one sentence.
    pub headline: String,
    /// How sure, in plain words (one item per line).
    pub details: Vec<String>,
    /// Design and data warnings that undermine the answer.
    pub warnings: Vec<String>,
    /// The one command to run next.
    pub next: Option<String>,
    /// The card's colour.
    pub tone: Tone,
}

/// An HTML report under construction.
#[derive(Clone, Debug)]
pub struct Page {
    title: String,
    verdict: Option<Verdict>,
    blocks: Vec<Block>,
}

impl Page {
    /// A page with a title (shown as the top heading and the window title).
    pub fn new(title: impl Into<String>) -> Page {
        Page {
            title: title.into(),
            verdict: None,
            blocks: Vec::new(),
        }
    }

    /// Sets the verdict card; it is drawn first, right under the title,
    /// wherever in the building of the page it is set.
    pub fn verdict(&mut self, v: Verdict) -> &mut Page {
        self.verdict = Some(v);
        self
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
        self.blocks
            .push(Block::Figure(Figure::new(name, caption, svg)));
        self
    }

    /// A figure of `plot` ([`Figure::plot`]: drawn again for a phone when
    /// it is wider than one).
    pub fn plot(
        &mut self,
        name: impl Into<String>,
        caption: impl Into<String>,
        plot: &dyn plot::Drawing,
    ) -> anyhow::Result<&mut Page> {
        self.blocks
            .push(Block::Figure(Figure::plot(name, caption, plot)?));
        Ok(self)
    }

    /// The colour key shared by every plot below it: ex, ey, ez and the
    /// two approach directions, each a swatch in its colour
    /// ([`plot::TARGET_COLOURS`], [`plot::DIRECTION_COLOURS`]).
    pub fn colour_key(&mut self) -> &mut Page {
        self.blocks.push(Block::Key);
        self
    }

    /// Figures side by side in a grid that fills the window's width.
    pub fn grid(&mut self, figures: Vec<Figure>) -> &mut Page {
        if !figures.is_empty() {
            self.blocks.push(Block::Grid(figures, GridKind::Small));
        }
        self
    }

    /// Figures side by side, two per row in a 1280 px window (x–y plots:
    /// smaller cells would shrink their text below reading size).
    pub fn grid_wide(&mut self, figures: Vec<Figure>) -> &mut Page {
        if !figures.is_empty() {
            self.blocks.push(Block::Grid(figures, GridKind::Wide));
        }
        self
    }

    fn figures(&self) -> impl Iterator<Item = &Figure> {
        self.blocks.iter().flat_map(|b| match b {
            Block::Figure(f) => std::slice::from_ref(f),
            Block::Grid(g, _) => g.as_slice(),
            _ => &[],
        })
    }

    /// Number of figures on the page.
    pub fn figure_count(&self) -> usize {
        self.figures().count()
    }

    /// The whole page as one HTML document.
    pub fn to_html(&self) -> String {
        let mut h = String::new();
        let _ = write!(
            h,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>{}</title>\n<style>{}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
            esc(&self.title),
            STYLE,
            esc(&self.title)
        );
        if let Some(v) = &self.verdict {
            write_verdict(&mut h, v);
        }
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
                    // A wide table scrolls inside its box; the page never
                    // gets wider than the window.
                    // Numbers align right (their digits line up), words
                    // left (a right-aligned sentence is hard to read) — by
                    // column: a column with any word in it is a text
                    // column, its header and its one number included
                    // (issue 28: "5" right-aligned under words).
                    let numeric: Vec<bool> = (0..header.len())
                        .map(|k| {
                            rows.iter()
                                .filter_map(|r| r.get(k))
                                .all(|c| is_number_cell(c))
                        })
                        .collect();
                    let class = |k: usize| {
                        if numeric.get(k).copied().unwrap_or(false) {
                            ""
                        } else {
                            " class=\"t\""
                        }
                    };
                    h.push_str("<div class=\"scroll\"><table>\n<thead><tr>");
                    for (k, c) in header.iter().enumerate() {
                        let _ = write!(h, "<th{}>{}</th>", class(k), esc(c));
                    }
                    h.push_str("</tr></thead>\n<tbody>\n");
                    for r in rows {
                        h.push_str("<tr>");
                        for (k, c) in r.iter().enumerate() {
                            let _ = write!(h, "<td{}>{}</td>", class(k), esc(c));
                        }
                        h.push_str("</tr>\n");
                    }
                    h.push_str("</tbody>\n</table></div>\n");
                }
                Block::Figure(f) => write_figure(&mut h, f),
                Block::Key => write_key(&mut h),
                Block::Grid(figs, kind) => {
                    h.push_str(match kind {
                        GridKind::Small => "<div class=\"grid\">\n",
                        GridKind::Wide => "<div class=\"grid wide\">\n",
                    });
                    for f in figs {
                        write_figure(&mut h, f);
                    }
                    h.push_str("</div>\n");
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
        for Figure { name, svg, .. } in self.figures() {
            {
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
                trueaxis_engine::files::write(&path, svg.as_bytes())?;
            }
        }
        let index = dir.join("index.html");
        trueaxis_engine::files::write(&index, self.to_html().as_bytes())?;
        Ok(index)
    }
}

/// The verdict card: `<section id="verdict">`, the first thing under the
/// title.
fn write_verdict(h: &mut String, v: &Verdict) {
    let tone = match v.tone {
        Tone::Good => "good",
        Tone::Action => "action",
        Tone::Unknown => "unknown",
    };
    let _ = write!(
        h,
        "<section id=\"verdict\" class=\"verdict {tone}\">\n<p class=\"headline\">{}</p>\n",
        esc(&v.headline)
    );
    if !v.details.is_empty() {
        h.push_str("<ul>\n");
        for d in &v.details {
            let _ = writeln!(h, "<li>{}</li>", esc(d));
        }
        h.push_str("</ul>\n");
    }
    if !v.warnings.is_empty() {
        h.push_str("<div class=\"undermine\"><p><b>What undermines it</b></p>\n<ul>\n");
        for w in &v.warnings {
            let _ = writeln!(h, "<li>{}</li>", esc(w));
        }
        h.push_str("</ul></div>\n");
    }
    if let Some(n) = &v.next {
        let _ = writeln!(
            h,
            "<p><b>Next</b></p>\n<pre class=\"next\">{}</pre>",
            esc(n)
        );
    }
    h.push_str("</section>\n");
}

/// The colour key: one swatch per target and per approach direction.
fn write_key(h: &mut String) {
    let hex = |c: plotters::style::RGBColor| format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2);
    h.push_str("<p class=\"key\">Colours on every plot: ");
    for (t, c) in ["ex", "ey", "ez"].iter().zip(plot::TARGET_COLOURS) {
        let _ = write!(
            h,
            "<span><i style=\"background:{}\"></i>{t}</span> ",
            hex(c)
        );
    }
    for (d, c) in ["approach +1", "approach −1"]
        .iter()
        .zip(plot::DIRECTION_COLOURS)
    {
        let _ = write!(
            h,
            "<span><i style=\"background:{}\"></i>{d}</span> ",
            hex(c)
        );
    }
    h.push_str("(a model, fit or mean: the darker shade of its target; held-out: dashed)</p>\n");
}

/// A figure with its caption and a link to its SVG file; its width is at
/// most the drawing's own (the SVG scales down to narrower windows).
fn write_figure(h: &mut String, f: &Figure) {
    let max = svg_width(&f.svg).map_or(String::new(), |w| format!(" style=\"max-width:{w}px\""));
    // With a phone drawing both are inlined, classed; the style shows one.
    let drawings = match &f.narrow {
        Some(narrow) => format!(
            "{}\n{}",
            with_class(strip_xml_declaration(&f.svg), "wide"),
            with_class(strip_xml_declaration(narrow), "narrow")
        ),
        None => strip_xml_declaration(&f.svg).to_string(),
    };
    let _ = write!(
        h,
        "<figure id=\"{}\"{max}>\n{drawings}\n<figcaption>{} <a href=\"{}.svg\">(SVG)</a></figcaption>\n</figure>\n",
        esc(&f.name),
        esc(&f.caption),
        esc(&f.name)
    );
}

/// `svg` with `class="…"` on its root element.
fn with_class(svg: &str, class: &str) -> String {
    match svg.find("<svg") {
        Some(i) => format!("{}<svg class=\"{class}\"{}", &svg[..i], &svg[i + 4..]),
        None => svg.to_string(),
    }
}

/// A cell that reads as a number (`2.0137`, `-6751`, `47 %`, `14.4×`, `—`).
fn is_number_cell(c: &str) -> bool {
    let c = c.trim();
    let short_number = c.chars().count() <= 16
        && !c.contains(' ')
        && c.chars()
            .next()
            .is_some_and(|f| f.is_ascii_digit() || matches!(f, '-' | '−' | '+' | '.'));
    c == "—" || short_number || (c.ends_with(" %") && c.len() <= 10)
}

/// The width of an SVG's `viewBox` (its drawing's width in user units).
fn svg_width(svg: &str) -> Option<u32> {
    let i = svg.find("viewBox=\"")? + "viewBox=\"".len();
    let v: Vec<&str> = svg[i..].split('"').next()?.split_whitespace().collect();
    v.get(2)?.parse::<f64>().ok().map(|w| w.round() as u32)
}

/// `1 row`, `2 rows`, `0 rows`: a count with its noun in the right number
/// (issue 28: "1 rows").
pub fn count(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// `a straightness scan`, `an arc scan`: the article a word takes.
pub fn a_or_an(word: &str) -> String {
    let an = word
        .chars()
        .next()
        .is_some_and(|c| "aeiouAEIOU".contains(c));
    format!("{} {word}", if an { "an" } else { "a" })
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

/// Print-friendly, dependency-free styling. Figures scale to the window
/// (`svg` at 100 % of a figure no wider than the drawing); a grid holds
/// small multiples; the verdict card stands out by colour and border. Text
/// breaks inside a long unbroken token (an effect string of 150 characters
/// in the simulate summary made the page 1400 px wide in a 1280 px window).
const STYLE: &str = "body{font-family:sans-serif;max-width:1500px;margin:1em auto;padding:0 1em;color:#222}\
p,li,figcaption,h1,h2,h3{overflow-wrap:break-word}\
h1{font-size:1.5em}h2{font-size:1.25em;border-bottom:1px solid #ccc;margin-top:1.6em}\
h3{font-size:1.05em}table{border-collapse:collapse;margin:.6em 0}\
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right;font-variant-numeric:tabular-nums}\
th{background:#f3f3f3}td.t,th.t{text-align:left}\
.scroll{max-width:100%;overflow-x:auto}\
figure{margin:.6em 0}figure svg{display:block;width:100%;height:auto}\
figcaption{font-size:.9em;color:#555;max-width:720px}pre{background:#f6f6f6;padding:.6em;overflow-x:auto}\
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(min(340px,100%),1fr));gap:.4em 1em}\
.grid.wide{grid-template-columns:repeat(auto-fill,minmax(min(560px,100%),1fr))}.grid figure{margin:0}\
figure>svg.narrow{display:none}\
@media (max-width:600px){body{padding:0 .5em;margin:.5em auto}h1{font-size:1.25em}th,td{padding:.2em .35em}figure>svg.wide{display:none}figure>svg.narrow{display:block}}\
.verdict{border:2px solid #999;border-left-width:10px;border-radius:6px;padding:.4em 1em;margin:1em 0;background:#fafafa}\
.verdict.good{border-color:#009e73;background:#eefaf5}.verdict.action{border-color:#d55e00;background:#fff4ec}\
.verdict.unknown{border-color:#e69f00;background:#fffaeb}\
.verdict .headline{font-size:1.25em;font-weight:bold;margin:.4em 0}\
.verdict .undermine{color:#7a3b00}\
.key{font-size:.9em;color:#444}.key span{white-space:nowrap;margin-right:.6em}\
.key i{display:inline-block;width:.9em;height:.9em;margin-right:.25em;vertical-align:-.1em;border-radius:2px}pre.next{white-space:pre-wrap;word-break:break-all;background:#fff;border:1px solid #ccc}";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plot_wider_than_a_phone_is_drawn_again_for_one() {
        // Issue 28: a 720 px plot scaled into a 390 px window had 5 px text.
        // Wider than a phone, a plot carries a drawing PHONE_WIDTH wide,
        // with its legend under it; the page shows one of the two by width.
        let wide = plot::XyPlot::new("t", "x (mm)", "e (µm)")
            .with(plot::Series::line("ex", vec![(0.0, 1.0), (1.0, 2.0)]));
        let f = Figure::plot("a", "c", &wide).unwrap();
        let narrow = f.narrow.as_deref().expect("a phone drawing");
        assert_eq!(svg_width(&f.svg), Some(plot::SIZE.0));
        assert_eq!(svg_width(narrow), Some(plot::PHONE_WIDTH));
        let mut p = Page::new("p");
        p.plot("a", "c", &wide).unwrap();
        let html = p.to_html();
        assert!(html.contains("<svg class=\"wide\"") && html.contains("<svg class=\"narrow\""));
        assert!(STYLE.contains("figure>svg.narrow{display:none}"));
        assert!(
            STYLE.contains("@media (max-width:600px)")
                && STYLE.contains("figure>svg.wide{display:none}figure>svg.narrow{display:block}")
        );
        // A drawing already as narrow as a phone is shown as it is.
        let small = plot::XyPlot {
            size: (plot::PHONE_WIDTH, 300),
            ..wide
        };
        assert!(Figure::plot("b", "c", &small).unwrap().narrow.is_none());
    }

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
    fn the_verdict_card_comes_first_wherever_it_is_set() {
        let mut p = Page::new("t");
        p.heading("Evidence")
            .figure("f", "c", "<svg viewBox=\"0 0 720 420\"></svg>".into());
        p.verdict(Verdict {
            headline: "Missing: a periodic error of ex".into(),
            details: vec!["ΔBIC −6751".into()],
            warnings: vec!["aliasing along y".into()],
            next: Some("trueaxis fit d.csv --model cubic19 --add 'p'".into()),
            tone: Tone::Action,
        });
        let html = p.to_html();
        let body = &html[html.find("</h1>").unwrap() + 5..];
        assert!(
            body.trim_start()
                .starts_with("<section id=\"verdict\" class=\"verdict action\">"),
            "{body}"
        );
        assert!(body.find("id=\"verdict\"").unwrap() < body.find("<h2>Evidence").unwrap());
        assert!(body.contains("What undermines it"));
        assert!(body.contains(
            "<pre class=\"next\">trueaxis fit d.csv --model cubic19 --add &#39;p&#39;</pre>"
        ));
        // A figure is no wider than its drawing and scales below it.
        assert!(body.contains("<figure id=\"f\" style=\"max-width:720px\">"));
        assert!(STYLE.contains("figure svg{display:block;width:100%;height:auto}"));
    }

    #[test]
    fn grids_hold_small_multiples_and_tables_scroll_inside() {
        let mut p = Page::new("t");
        let f = |n: &str| Figure::new(n, "c", "<svg viewBox=\"0 0 460 380\"></svg>".into());
        p.grid(vec![f("a"), f("b")]).table(
            &["add", "ΔBIC", "gain", "evidence"],
            vec![vec![
                "periodic:target=ex".into(),
                "-6751".into(),
                "47 %".into(),
                "periodogram of the ex residual".into(),
            ]],
        );
        let html = p.to_html();
        assert!(html.contains("<td class=\"t\">periodic:target=ex</td><td>-6751</td><td>47 %</td><td class=\"t\">periodogram of the ex residual</td>"), "{html}");
        assert!(
            html.contains("<th class=\"t\">add</th><th>ΔBIC</th>"),
            "{html}"
        );
        assert!(html.contains("<div class=\"grid\">\n<figure id=\"a\""));
        assert!(html.contains("<div class=\"scroll\"><table>"));
        assert_eq!(p.figure_count(), 2);
    }

    #[test]
    fn a_column_with_words_is_left_aligned_whole() {
        // A value column holding "VMC-1", "A. Tester" and "5": the number
        // aligns with the words, not alone at the right (issue 28).
        let mut p = Page::new("t");
        p.table(
            &["what", "value"],
            vec![
                vec!["Machine".into(), "VMC-1".into()],
                vec!["DEC".into(), "5".into()],
            ],
        );
        let html = p.to_html();
        assert!(
            html.contains("<td class=\"t\">DEC</td><td class=\"t\">5</td>"),
            "{html}"
        );
        assert!(html.contains("<th class=\"t\">value</th>"), "{html}");
    }

    #[test]
    fn counts_and_articles_read_as_english() {
        assert_eq!(count(1, "row"), "1 row");
        assert_eq!(count(3, "row"), "3 rows");
        assert_eq!(count(0, "point"), "0 points");
        assert_eq!(a_or_an("arc"), "an arc");
        assert_eq!(a_or_an("straightness"), "a straightness");
    }

    #[test]
    fn pages_fit_a_phone() {
        // Without the viewport a phone lays the page out 980 px wide and
        // shrinks its text to a third; a grid cell wider than the window
        // made five pages 576 px wide at 390 px (issue 28).
        let html = Page::new("t").to_html();
        assert!(html
            .contains("<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"));
        assert!(STYLE.contains("minmax(min(340px,100%),1fr)"));
        assert!(STYLE.contains("minmax(min(560px,100%),1fr)"));
        assert!(!STYLE.contains("minmax(560px"));
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
