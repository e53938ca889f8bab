//! `cargo xtask test-browser` (part of `cargo xtask test`): every kind of
//! report page (the demo's compare, diagnose, history and final pages;
//! ISO 230-2 from a simulated run and from an `.rtl`; the on-machine
//! pages — probe 2-D and 3-D, separate reversal / three-probe / multi-step,
//! workpiece, diagnose-part; a printer bed's diagnose page) opened in a
//! real browser — headless Chromium at 1280 px (a laptop) and at 390 px
//! (a phone) — and checked the way a person would look at them: the page
//! declares a viewport (else a phone lays it out 980 px wide and shrinks
//! the text), every figure is drawn (has a size) and every image loaded,
//! nothing is wider than the window, the verdict card is the first thing
//! under the title and visible without scrolling, the page weight and the
//! time to lay it out stay within limits. A screenshot of each page at
//! each width is written to `out/screens/<page>-<width>.png` to look at.
//!
//! How: a copy of each page gets a small script at the end of its body that
//! measures the laid-out page (`scrollWidth`, each figure's box, each
//! `<img>`'s `naturalWidth`, the verdict's position, `performance.now()`)
//! and writes the figures as `key=value` lines into a `<pre>`;
//! `chromium --dump-dom` prints the DOM after load and the lines are read
//! back from it. No driver, no network, no npm: only the `chromium` Debian
//! package (`cargo xtask setup` installs it as root).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::{root, Result};

/// The window widths the pages are checked at: a laptop (the issue's
/// 1400 px screen cut the 1440 px colour bar off) and a phone held upright
/// (issue 28: five pages were 576 px wide at 390 px).
pub const WIDTHS_PX: [u32; 2] = [1280, 390];
/// A page (HTML with its inlined SVGs) may weigh at most this much.
pub const MAX_PAGE_BYTES: u64 = 4_000_000;
/// From navigation start to the end of the body, laid out, at most.
pub const MAX_LAYOUT_MS: f64 = 8_000.0;
/// One Chromium run (start, load, dump) at most, wall clock.
pub const MAX_BROWSER_S: u64 = 120;

/// The browser: `$CHROMIUM`, else the first of the Debian and the usual
/// names that runs.
pub fn chromium() -> Option<String> {
    let mut names: Vec<String> = std::env::var("CHROMIUM").ok().into_iter().collect();
    names.extend(
        ["chromium", "chromium-browser", "google-chrome"]
            .iter()
            .map(|s| s.to_string()),
    );
    names.into_iter().find(|n| {
        Command::new(n)
            .arg("--version")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    })
}

/// What the in-page script measured.
#[derive(Debug, Default, PartialEq)]
pub struct Measure {
    /// `window.innerWidth`.
    pub viewport: f64,
    /// The page has `<meta name="viewport" content="width=device-width…">`.
    pub viewport_meta: bool,
    /// `document.documentElement.scrollWidth`.
    pub scroll_width: f64,
    /// `document.documentElement.scrollHeight` (reported, not limited).
    pub height: f64,
    /// Figures (`figure > svg`) on the page.
    pub figures: usize,
    /// Figures drawn with no size, or reaching past the window.
    pub bad_figures: Vec<String>,
    /// `<img>` elements, and those not loaded (`naturalWidth` 0).
    pub images: usize,
    pub broken_images: Vec<String>,
    /// The element right after the `<h1>` is `#verdict`.
    pub verdict_first: bool,
    /// Top of the verdict card, px (must be inside the first screen).
    pub verdict_top: f64,
    /// `performance.now()` when the end of the body was laid out.
    pub layout_ms: f64,
    /// Top of the first working-volume overview map (`figure#overview_…`,
    /// diagnose's "Where the model fails"), px; None when the page has none.
    pub overview_top: Option<f64>,
    /// The smallest text drawn in a figure, px (font size × the drawing's
    /// scale), and the figure's id; None when no figure has text.
    pub smallest_text: Option<(f64, String)>,
}

/// Text in a figure drawn smaller than this (px) cannot be read: a 720 px
/// plot scaled into a phone had 5 px labels (issue 28).
pub const MIN_TEXT_PX: f64 = 7.5;

/// The overview of where the model fails must start within this many px of
/// the top (the 2000 px window's first screen): diagnose's page says where
/// before the tables and the evidence.
pub const MAX_OVERVIEW_TOP: f64 = 2000.0;

/// The script injected at the end of the page's body.
const SCRIPT: &str = r#"<script>
(function () {
  var out = [];
  var vw = window.innerWidth;
  out.push('viewport=' + vw);
  var meta = document.querySelector('meta[name="viewport"]');
  out.push('viewport_meta=' + (meta !== null && /width=device-width/.test(meta.getAttribute('content') || '')));
  out.push('scroll_width=' + document.documentElement.scrollWidth);
  out.push('height=' + document.documentElement.scrollHeight);
  // A figure may hold a drawing per window width (svg.wide, svg.narrow):
  // the one the style hides is not on the page.
  var figs = Array.prototype.filter.call(document.querySelectorAll('figure > svg'), function (s) {
    return getComputedStyle(s).display !== 'none';
  });
  out.push('figures=' + figs.length);
  var smallest = Infinity, smallestIn = '';
  figs.forEach(function (s) {
    var b = s.getBoundingClientRect();
    if (b.width < 10 || b.height < 10 || b.right > vw + 0.5) {
      out.push('bad_figure=' + s.parentElement.id + ' ' + Math.round(b.width) + 'x' + Math.round(b.height) + ' right ' + Math.round(b.right));
    }
    // Text as drawn: its font size times the drawing's scale.
    var vb = s.viewBox && s.viewBox.baseVal;
    if (!vb || !(vb.width > 0)) { return; }
    var k = b.width / vb.width;
    s.querySelectorAll('text').forEach(function (t) {
      if (!t.textContent.trim()) { return; }
      var fs = parseFloat(t.getAttribute('font-size') || getComputedStyle(t).fontSize);
      if (fs > 0 && fs * k < smallest) { smallest = fs * k; smallestIn = s.parentElement.id; }
    });
  });
  if (smallest < Infinity) { out.push('smallest_text=' + smallest.toFixed(2) + ' ' + smallestIn); }
  var imgs = document.querySelectorAll('img');
  out.push('images=' + imgs.length);
  imgs.forEach(function (i) {
    if (!i.complete || i.naturalWidth === 0) { out.push('broken_image=' + i.getAttribute('src')); }
  });
  var h1 = document.querySelector('body > h1');
  var first = h1 ? h1.nextElementSibling : null;
  out.push('verdict_first=' + (first !== null && first.id === 'verdict'));
  var v = document.getElementById('verdict');
  out.push('verdict_top=' + (v ? v.getBoundingClientRect().top : -1));
  var ov = document.querySelector('figure[id^="overview_"]');
  if (ov) { out.push('overview_top=' + ov.getBoundingClientRect().top); }
  out.push('layout_ms=' + performance.now());
  var pre = document.createElement('pre');
  pre.id = 'browser-check';
  pre.textContent = '\n' + out.join('\n') + '\n';
  document.body.appendChild(pre);
})();
</script>
"#;

/// Reads the `key=value` lines of the `<pre id="browser-check">` in a
/// dumped DOM.
pub fn parse(dom: &str) -> std::result::Result<Measure, String> {
    let start = dom
        .find("id=\"browser-check\">")
        .ok_or("the page's check script did not run (no #browser-check in the DOM)")?;
    let body = &dom[start..];
    let end = body.find("</pre>").unwrap_or(body.len());
    let mut m = Measure::default();
    for line in body[..end].lines().skip(1) {
        let Some((k, v)) = line.split_once('=') else {
            continue;
        };
        let num = || v.trim().parse::<f64>().map_err(|e| format!("{k}={v}: {e}"));
        match k {
            "viewport" => m.viewport = num()?,
            "viewport_meta" => m.viewport_meta = v.trim() == "true",
            "scroll_width" => m.scroll_width = num()?,
            "height" => m.height = num()?,
            "figures" => m.figures = num()? as usize,
            "bad_figure" => m.bad_figures.push(v.to_string()),
            "images" => m.images = num()? as usize,
            "broken_image" => m.broken_images.push(v.to_string()),
            "verdict_first" => m.verdict_first = v.trim() == "true",
            "verdict_top" => m.verdict_top = num()?,
            "layout_ms" => m.layout_ms = num()?,
            "overview_top" => m.overview_top = Some(num()?),
            "smallest_text" => {
                let (px, id) = v.split_once(' ').unwrap_or((v, ""));
                let px = px
                    .trim()
                    .parse::<f64>()
                    .map_err(|e| format!("{k}={v}: {e}"))?;
                m.smallest_text = Some((px, id.trim().to_string()));
            }
            _ => {}
        }
    }
    Ok(m)
}

/// Diagnose's page must show where the model fails on its first screen.
pub fn overview_failures(m: &Measure) -> Vec<String> {
    match m.overview_top {
        None => vec!["no working-volume overview (figure#overview_…): the page does not say where the model fails".into()],
        Some(top) if top > MAX_OVERVIEW_TOP => vec![format!(
            "the working-volume overview starts at {top:.0} px: not on the first screen ({MAX_OVERVIEW_TOP:.0} px)"
        )],
        Some(_) => Vec::new(),
    }
}

/// Every way the page fails the check at window width `width`, in words
/// (empty: it passes).
pub fn failures(m: &Measure, page_bytes: u64, width: u32) -> Vec<String> {
    let mut f = Vec::new();
    if (m.viewport - f64::from(width)).abs() > 0.5 {
        f.push(format!(
            "the window was {} px wide, not {width}: the check did not run at the width it means",
            m.viewport
        ));
    }
    if !m.viewport_meta {
        f.push(
            "no <meta name=\"viewport\" content=\"width=device-width\">: a phone lays the page out 980 px wide and shrinks it"
                .into(),
        );
    }
    if m.scroll_width > m.viewport + 0.5 {
        f.push(format!(
            "the page is {} px wide in a {} px window: something overflows (a horizontal scroll bar)",
            m.scroll_width, m.viewport
        ));
    }
    if m.figures == 0 {
        f.push("no figure on the page".into());
    }
    for b in &m.bad_figures {
        f.push(format!("figure not drawn inside the window: {b}"));
    }
    if let Some((px, id)) = m.smallest_text.as_ref().filter(|t| t.0 < MIN_TEXT_PX) {
        f.push(format!(
            "text in figure {id} is drawn {px:.1} px high, below the {MIN_TEXT_PX} px that can be read"
        ));
    }
    for i in &m.broken_images {
        f.push(format!("image did not load: {i}"));
    }
    if !m.verdict_first {
        f.push("the verdict card is not the first thing under the title".into());
    }
    if !(0.0..=600.0).contains(&m.verdict_top) {
        f.push(format!(
            "the verdict card starts at {} px: not on the first screen",
            m.verdict_top
        ));
    }
    if m.layout_ms > MAX_LAYOUT_MS {
        f.push(format!(
            "laid out after {:.0} ms, above the {MAX_LAYOUT_MS:.0} ms allowed",
            m.layout_ms
        ));
    }
    if page_bytes > MAX_PAGE_BYTES {
        f.push(format!(
            "the page weighs {page_bytes} bytes, above the {MAX_PAGE_BYTES} allowed"
        ));
    }
    f
}

/// Runs `cmd` with a time limit, returning its stdout.
fn output_within(cmd: &mut Command, limit: Duration) -> std::result::Result<String, String> {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("cannot start the browser: {e}"))?;
    let mut stdout = child.stdout.take().ok_or("no stdout")?;
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut stdout, &mut s);
        s
    });
    let t0 = Instant::now();
    loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            let out = reader.join().unwrap_or_default();
            return if status.success() {
                Ok(out)
            } else {
                Err(format!("the browser failed ({status})"))
            };
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("the browser did not finish within {limit:?}"));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Chromium's smallest window width: a narrower `--window-size` is widened
/// to it, so narrower widths are checked in an iframe ([`frame_page`]).
pub const MIN_WINDOW_PX: u32 = 500;

/// A page holding `src` (a file beside it) in an iframe `width` px wide
/// and 2000 px high; when the frame has loaded, the `#browser-check` text
/// inside it is copied into this page's own `<pre id="browser-check">`
/// (`--dump-dom` prints the top page only). The grey right of the frame is
/// what the phone does not show.
pub fn frame_page(src: &str, width: u32) -> String {
    format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><style>body{{margin:0;background:#777}}\
iframe{{border:0;display:block;background:#fff}}</style>\n<script>\nfunction copyCheck(f) {{\n\
  var d = null; try {{ d = f.contentDocument; }} catch (e) {{}}\n\
  var p = d ? d.getElementById('browser-check') : null;\n\
  if (!p) {{ return; }}\n\
  var pre = document.createElement('pre');\n  pre.id = 'browser-check';\n\
  pre.textContent = p.textContent;\n  document.body.appendChild(pre);\n}}\n</script></head>\n\
<body><iframe src=\"{}\" width=\"{width}\" height=\"2000\" onload=\"copyCheck(this)\"></iframe></body></html>\n",
        src.replace('"', "%22")
    )
}

/// Common flags: headless, no sandbox (root in a container), no GPU, the
/// window size (at least [`MIN_WINDOW_PX`]), nothing from the network;
/// file pages may read their frames (the narrow-width check).
fn browser_cmd(browser: &str, width: u32) -> Command {
    let mut c = Command::new(browser);
    c.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--hide-scrollbars",
        "--no-first-run",
        "--allow-file-access-from-files",
        &format!("--window-size={},2000", width.max(MIN_WINDOW_PX)),
    ]);
    c
}

/// Checks one page in a window `width` px wide; writes its screenshot to
/// `shot`. Returns the measure and the failures.
pub fn check_page(
    browser: &str,
    page: &Path,
    shot: &Path,
    width: u32,
) -> std::result::Result<(Measure, u64, f64, Vec<String>), String> {
    // file:// needs an absolute path.
    let page = &page
        .canonicalize()
        .map_err(|e| format!("{}: {e}", page.display()))?;
    let html = std::fs::read_to_string(page).map_err(|e| format!("{}: {e}", page.display()))?;
    let bytes = html.len() as u64;
    let end = html
        .rfind("</body>")
        .ok_or_else(|| format!("{}: no </body>", page.display()))?;
    // The copy sits beside the page so that relative links resolve alike.
    let copy = page.with_file_name("index.browser-check.html");
    let injected = format!("{}{SCRIPT}{}", &html[..end], &html[end..]);
    std::fs::write(&copy, injected).map_err(|e| format!("{}: {e}", copy.display()))?;
    let url = |p: &Path| format!("file://{}", p.display());
    // Below Chromium's smallest window (500 px) the page is laid out in an
    // iframe of the width asked for, inside a frame page that copies the
    // measure out of it (the frame's innerWidth is the width a phone
    // gives the page). The frame sits beside the page as well.
    let framed = |target: &Path, name: &str| -> std::result::Result<PathBuf, String> {
        if width >= MIN_WINDOW_PX {
            return Ok(target.to_path_buf());
        }
        let frame = page.with_file_name(name);
        let file = target.file_name().unwrap_or_default().to_string_lossy();
        std::fs::write(&frame, frame_page(&file, width))
            .map_err(|e| format!("{}: {e}", frame.display()))?;
        Ok(frame)
    };
    let check = framed(&copy, "index.browser-frame.html")?;
    let t0 = Instant::now();
    let dom = output_within(
        browser_cmd(browser, width)
            .arg("--dump-dom")
            .arg(url(&check)),
        Duration::from_secs(MAX_BROWSER_S),
    );
    let wall_s = t0.elapsed().as_secs_f64();
    let _ = std::fs::remove_file(&copy);
    if check != copy {
        let _ = std::fs::remove_file(&check);
    }
    let m = parse(&dom?)?;
    if let Some(dir) = shot.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let view = framed(page, "index.browser-frame.html")?;
    let shot_run = output_within(
        browser_cmd(browser, width)
            .arg(format!("--screenshot={}", shot.display()))
            .arg(url(&view)),
        Duration::from_secs(MAX_BROWSER_S),
    );
    if view != *page {
        let _ = std::fs::remove_file(&view);
    }
    shot_run?;
    let f = failures(&m, bytes, width);
    Ok((m, bytes, wall_s, f))
}

/// Every page kind, with a short name for the screenshot, as
/// [`write_pages`] lays them out under `out`: the demo's four pages, then
/// one page of each other kind under `out/pages/<name>/`.
fn pages(out: &Path) -> Vec<(&'static str, PathBuf)> {
    // `--pages DIR` of a demo's own folder (DIR/report/…, the layout
    // before every page kind was checked): its four pages.
    let own_demo = out.join("report").join("index.html").is_file();
    let r = if own_demo {
        out.join("report")
    } else {
        out.join("demo").join("report")
    };
    let mut v = vec![
        ("compare", r.join("index.html")),
        ("diagnose", r.join("diagnose").join("index.html")),
        ("history", r.join("history").join("index.html")),
        ("final", r.join("final").join("index.html")),
    ];
    if !own_demo {
        for (name, _) in PAGE_COMMANDS {
            v.push((name, out.join("pages").join(name).join("index.html")));
        }
    }
    v
}

/// The commands that write the pages beside the demo's, run in `out` after
/// `simulate --scenario on-machine -o om/`, `simulate --plan iso230:x` and
/// `simulate --scenario volumetric-lines` (fitted with rigid21)
/// (`{data}` is the tests' data folder, the report folder is appended as
/// `--report pages/<name>`).
const PAGE_COMMANDS: [(&str, &[&str]); 12] = [
    ("iso230", &["iso230", "iso.csv"]),
    ("iso230-rtl", &["iso230", "{data}/iso_worked.rtl"]),
    (
        "probe-2d",
        &[
            "probe",
            "calibrate",
            "om/ball.csv",
            "--ball-diameter-mm",
            "4",
            "-o",
            "probe.json",
        ],
    ),
    (
        "probe-3d",
        &[
            "probe",
            "calibrate",
            "om/ball3d.csv",
            "--ball-diameter-mm",
            "4",
            "--plane",
            "xyz",
            "-o",
            "probe3d.json",
        ],
    ),
    (
        "separate-reversal",
        &[
            "separate",
            "reversal",
            "om/run0.csv",
            "om/run180.csv",
            "-o",
            "rev.csv",
        ],
    ),
    (
        "separate-three-probe",
        &[
            "separate",
            "three-probe",
            "om/three-probe.csv",
            "--angles-deg",
            "0,99.84,202.5",
            "-o",
            "tp.csv",
        ],
    ),
    (
        "separate-multi-step",
        &[
            "separate",
            "multi-step",
            "om/multi-step.csv",
            "-o",
            "ms.csv",
        ],
    ),
    ("workpiece", &["workpiece", "om/grinder.csv"]),
    (
        "diagnose-part",
        &[
            "diagnose-part",
            "om/run0.csv",
            "--reversal",
            "om/run180.csv",
        ],
    ),
    ("bed", &["diagnose", "bed.csv", "--model", "bed.json"]),
    (
        "bed-compare",
        &["compare", "bed.csv", "--model", "bed.json"],
    ),
    // The rigid21 page: laser lines' errors and what they cannot know.
    ("volumetric", &["compare", "vol.csv", "--model", "vol.json"]),
];

/// Runs `bin args…` in `dir`, failing with its stderr.
fn run_in(dir: &Path, bin: &Path, args: &[&str]) -> Result<()> {
    let out = Command::new(bin)
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .output()
        .map_err(|e| format!("cannot start {}: {e}", bin.display()))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`trueaxis {}` failed ({}): {}",
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ))
    }
}

/// Builds the CLI (debug) and writes every page kind into `out`: the demo
/// into `out/demo`, the rest into `out/pages/<name>`.
fn write_pages(root: &Path, out: &Path) -> Result<()> {
    let args = ["build", "--quiet", "-p", "trueaxis"];
    eprintln!("\n$ cargo {}", args.join(" "));
    let status = Command::new("cargo")
        .args(args)
        .current_dir(root)
        .status()
        .map_err(|e| format!("cannot start cargo: {e}"))?;
    if !status.success() {
        return Err(format!("`cargo {}` failed ({status})", args.join(" ")));
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"));
    let bin = target.join("debug").join("trueaxis");
    if out.exists() {
        std::fs::remove_dir_all(out).map_err(|e| format!("remove {}: {e}", out.display()))?;
    }
    std::fs::create_dir_all(out).map_err(|e| format!("create {}: {e}", out.display()))?;
    // --json: the story goes to stderr, the summary (one long JSON line)
    // to a file beside the pages rather than the terminal.
    eprintln!("$ trueaxis demo --out demo --json  (in {})", out.display());
    let summary = out.join("demo.json");
    let file = std::fs::File::create(&summary)
        .map_err(|e| format!("create {}: {e}", summary.display()))?;
    let status = Command::new(&bin)
        .args(["demo", "--out", "demo", "--json"])
        .current_dir(out)
        .stdout(file)
        .status()
        .map_err(|e| format!("cannot start {}: {e}", bin.display()))?;
    if !status.success() {
        return Err(format!("`trueaxis demo` failed ({status})"));
    }
    let data = root
        .join("host-tool")
        .join("cli")
        .join("tests")
        .join("data");
    let data_s = data.to_string_lossy().into_owned();
    let bed = format!("{data_s}/bed_heightmap.csv");
    let setup: [&[&str]; 6] = [
        &["simulate", "--scenario", "on-machine", "-o", "om/"],
        &[
            "simulate", "--plan", "iso230:x", "--seed", "2", "-o", "iso.csv",
        ],
        &["import", &bed, "-o", "bed.csv"],
        &["fit", "bed.csv", "--model", "cubic19", "-o", "bed.json"],
        &[
            "simulate",
            "--scenario",
            "volumetric-lines",
            "-o",
            "vol.csv",
        ],
        &["fit", "vol.csv", "--model", "rigid21", "-o", "vol.json"],
    ];
    for args in setup {
        run_in(out, &bin, args)?;
    }
    for (name, args) in PAGE_COMMANDS {
        let report = format!("pages/{name}");
        let mut a: Vec<String> = args.iter().map(|s| s.replace("{data}", &data_s)).collect();
        a.extend(["--report".into(), report]);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        eprintln!("$ trueaxis {}", a.join(" "));
        run_in(out, &bin, &a)?;
    }
    Ok(())
}

/// `cargo xtask test-browser [--pages DIR]`: every page kind (debug build)
/// into `out/browser`, then every page checked in Chromium at each of
/// [`WIDTHS_PX`]; screenshots in `out/screens/<page>-<width>.png`.
/// `--pages DIR` checks the pages already written to DIR by an earlier run
/// (no commands run) — an older build's, say; DIR may also be a demo's own
/// `--out` folder (its four pages are checked).
pub fn test(args: &[String]) -> Result<()> {
    let browser = chromium().ok_or(
        "no Chromium found (chromium, chromium-browser, google-chrome or $CHROMIUM): \
         run `sudo cargo xtask setup` (installs the Debian package `chromium`)",
    )?;
    let root = root();
    let given = match args {
        [] => None,
        [flag, dir] if flag == "--pages" => Some(PathBuf::from(dir)),
        _ => {
            return Err(format!(
                "test-browser: unexpected arguments {args:?} (usage: test-browser [--pages DIR])"
            ))
        }
    };
    let screens = match &given {
        Some(dir) => dir.join("screens"),
        None => root.join("out").join("screens"),
    };
    let out = match given {
        Some(dir) => dir,
        None => {
            let out = root.join("out").join("browser");
            write_pages(&root, &out)?;
            out
        }
    };
    let mut failed = Vec::new();
    for (name, page) in pages(&out) {
        for width in WIDTHS_PX {
            let shot = screens.join(format!("{name}-{width}.png"));
            let (m, bytes, wall_s, mut f) = check_page(&browser, &page, &shot, width)
                .map_err(|e| format!("{name} page ({}): {e}", page.display()))?;
            if name == "diagnose" && width == WIDTHS_PX[0] {
                f.extend(overview_failures(&m));
            }
            eprintln!(
                "{name:<21} {width:>4} px {:>5.2} MB  laid out in {:>5.0} ms (browser {wall_s:.1} s)  {} figures  smallest text {}  width {}/{} px  height {} px  verdict first: {}  {}",
                bytes as f64 / 1e6,
                m.layout_ms,
                m.figures,
                m.smallest_text
                    .as_ref()
                    .map_or("—".to_string(), |t| format!("{:.1} px", t.0)),
                m.scroll_width,
                m.viewport,
                m.height,
                m.verdict_first,
                if f.is_empty() { "ok" } else { "FAILED" }
            );
            for x in &f {
                eprintln!("    {x}");
            }
            if !f.is_empty() {
                failed.push(format!(
                    "{name} at {width} px ({}): {}",
                    page.display(),
                    f.join("; ")
                ));
            }
        }
    }
    eprintln!("screenshots: {}", screens.display());
    if failed.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "report pages fail in the browser:\n  {}",
            failed.join("\n  ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn good() -> Measure {
        Measure {
            viewport: 1280.0,
            viewport_meta: true,
            scroll_width: 1280.0,
            height: 5000.0,
            figures: 3,
            bad_figures: vec![],
            images: 0,
            broken_images: vec![],
            verdict_first: true,
            verdict_top: 70.0,
            layout_ms: 400.0,
            overview_top: None,
            smallest_text: Some((11.0, "a".into())),
        }
    }

    #[test]
    fn dumped_dom_is_read_back() {
        let dom = "<html><body><h1>t</h1><pre id=\"browser-check\">\nviewport=1280\nviewport_meta=true\nscroll_width=1295\nheight=9000\nfigures=2\nbad_figure=map_ex 1440x420 right 1460\nimages=1\nbroken_image=a.png\nverdict_first=false\nverdict_top=812.5\nlayout_ms=123.4\n</pre></body></html>";
        let m = parse(dom).unwrap();
        assert_eq!(m.viewport, 1280.0);
        assert!(m.viewport_meta);
        assert_eq!(m.scroll_width, 1295.0);
        assert_eq!(m.height, 9000.0);
        assert_eq!(m.figures, 2);
        assert_eq!(m.bad_figures, vec!["map_ex 1440x420 right 1460"]);
        assert_eq!(m.broken_images, vec!["a.png"]);
        assert!(!m.verdict_first);
        assert_eq!(m.verdict_top, 812.5);
        assert!(parse("<html></html>").is_err());
    }

    #[test]
    fn a_phone_width_is_checked_in_a_frame_and_every_page_kind_is_listed() {
        // Chromium widens a window below 500 px: 390 px is laid out in an
        // iframe that wide, whose measure the frame page copies out.
        let f = frame_page("index.browser-check.html", 390);
        assert!(f.contains("<iframe src=\"index.browser-check.html\" width=\"390\""));
        assert!(f.contains("getElementById('browser-check')"));
        assert!(WIDTHS_PX.contains(&390) && WIDTHS_PX.contains(&1280));
        const { assert!(390 < MIN_WINDOW_PX) };
        let names: Vec<&str> = pages(Path::new("/nowhere")).iter().map(|p| p.0).collect();
        for kind in [
            "compare",
            "diagnose",
            "history",
            "final",
            "iso230",
            "probe-2d",
            "probe-3d",
            "separate-reversal",
            "separate-three-probe",
            "separate-multi-step",
            "workpiece",
            "diagnose-part",
            "bed",
        ] {
            assert!(names.contains(&kind), "{kind} is not checked");
        }
    }

    #[test]
    fn a_diagnose_page_must_say_where_the_model_fails_on_its_first_screen() {
        let dom = "<pre id=\"browser-check\">\noverview_top=812.5\nlayout_ms=3\n</pre>";
        let m = parse(dom).unwrap();
        assert_eq!(m.overview_top, Some(812.5));
        assert!(overview_failures(&m).is_empty());
        let none = parse("<pre id=\"browser-check\">\nlayout_ms=3\n</pre>").unwrap();
        assert!(overview_failures(&none)[0].contains("no working-volume overview"));
        let low = Measure {
            overview_top: Some(2400.0),
            ..m
        };
        assert!(overview_failures(&low)[0].contains("not on the first screen"));
    }

    #[test]
    fn each_failure_is_named() {
        assert!(failures(&good(), 1000, 1280).is_empty());
        let cases: Vec<(Measure, u64, &str)> = vec![
            (
                Measure {
                    scroll_width: 1460.0,
                    ..good()
                },
                1000,
                "overflows",
            ),
            (
                Measure {
                    bad_figures: vec!["x".into()],
                    ..good()
                },
                1000,
                "figure not drawn",
            ),
            (
                Measure {
                    broken_images: vec!["a.png".into()],
                    ..good()
                },
                1000,
                "did not load",
            ),
            (
                Measure {
                    verdict_first: false,
                    ..good()
                },
                1000,
                "not the first thing",
            ),
            (
                Measure {
                    verdict_top: 900.0,
                    ..good()
                },
                1000,
                "first screen",
            ),
            (
                Measure {
                    layout_ms: 9000.0,
                    ..good()
                },
                1000,
                "laid out after",
            ),
            (good(), MAX_PAGE_BYTES + 1, "weighs"),
            (
                Measure {
                    smallest_text: Some((4.2, "history".into())),
                    ..good()
                },
                1000,
                "below the 7.5 px",
            ),
            (
                Measure {
                    viewport_meta: false,
                    ..good()
                },
                1000,
                "viewport",
            ),
            (
                Measure {
                    viewport: 800.0,
                    scroll_width: 800.0,
                    ..good()
                },
                1000,
                "window was",
            ),
        ];
        for (m, bytes, want) in cases {
            let f = failures(&m, bytes, 1280);
            assert_eq!(f.len(), 1, "{want}: {f:?}");
            assert!(f[0].contains(want), "{want}: {f:?}");
        }
    }
}
