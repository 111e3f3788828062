//! The report of a set of experiment results, all from the same `result.json` files: the
//! headline summary (one row per published figure: ours, published, better or worse) that opens
//! every report and fills the README's generated section ([`update_markdown`]); `report.md` and
//! `report.html` (the summary, then every table with its figures); the results page
//! `docs/results.md` ([`results_page`]: the summary, then every table and its notes). Every table,
//! in Markdown and in HTML, comes from [`tables`]: a result's rows without a variant as one table
//! of quantities, and the rows of each table of variants as one line per variant and one column
//! per quantity.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use plot::viewer::escape_html;

use crate::{ExperimentResult, Row, Size};

/// The experiments' references: where the published figures come from.
const SOURCES: &str = "Published figures: Mendizabal, Márquez-Neila & Cotin, *Simulation of hyperelastic \
materials in real-time using deep learning*, Medical Image Analysis 59 (2020) (liver forces, beam transfer, beam \
sparse input); Brunet, Mendizabal et al., *Physics-based deep neural network for augmented reality during liver \
surgery*, MICCAI 2019 (registration TRE, solve times); Mendizabal, *Data-driven simulation for augmented \
surgery*, PhD thesis, Université de Strasbourg, 2020 (ROUKF identification; Peterlík et al., MICCAI 2017 for \
the boundary springs).";

/// A table of a report: the cells of its heading and of its lines, as plain text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Table {
    /// The heading's cells.
    pub header: Vec<String>,
    /// The lines' cells, as many as the heading's.
    pub lines: Vec<Vec<String>>,
}

impl Table {
    /// The table in Markdown, its pipes escaped.
    pub fn markdown(&self) -> String {
        let line = |cells: &[String]| {
            let cells: Vec<String> = cells.iter().map(|c| c.replace('|', "\\|")).collect();
            format!("| {} |\n", cells.join(" | "))
        };
        let mut s = line(&self.header);
        s.push_str(&line(&vec!["---".to_string(); self.header.len()]));
        for cells in &self.lines {
            s.push_str(&line(cells));
        }
        s
    }

    /// The table in HTML, its text escaped.
    pub fn html(&self) -> String {
        let line = |tag: &str, cells: &[String]| {
            let cells: String = cells.iter().map(|c| format!("<{tag}>{}</{tag}>", escape_html(c))).collect();
            format!("<tr>{cells}</tr>\n")
        };
        let mut s = format!("<table>{}", line("th", &self.header));
        for cells in &self.lines {
            s.push_str(&line("td", cells));
        }
        s.push_str("</table>\n");
        s
    }
}

/// What a cell shows where there is nothing: no published figure, no figure of a variant.
const NONE: &str = "—";

/// The tables of a result's rows, in the order of their first rows: the rows without a variant in
/// one table (quantity, augsim, published), and the rows of each [`Row::table`] in a table with
/// one line per variant and one column per quantity. A quantity's published figure, where it is
/// the same for every variant, is shown once, on a last line "published"; where it differs, each
/// variant's is shown in a last column "published".
pub fn tables(rows: &[Row]) -> Vec<Table> {
    // The table of a row: `None` for the table of quantities.
    fn key(r: &Row) -> Option<&str> {
        (!r.variant.is_empty()).then_some(r.table.as_str())
    }
    let mut keys: Vec<Option<&str>> = Vec::new();
    for r in rows {
        if !keys.contains(&key(r)) {
            keys.push(key(r));
        }
    }
    keys.into_iter()
        .map(|k| {
            let rows: Vec<&Row> = rows.iter().filter(|r| key(r) == k).collect();
            match k {
                None => Table {
                    header: vec!["quantity".into(), "augsim".into(), "published".into()],
                    lines: rows
                        .iter()
                        .map(|r| vec![r.quantity.clone(), r.ours.clone(), or_none(&r.published)])
                        .collect(),
                },
                Some(name) => variants_table(name, &rows),
            }
        })
        .collect()
}

/// `text`, or [`NONE`] where it is empty.
fn or_none(text: &str) -> String {
    if text.is_empty() { NONE } else { text }.to_string()
}

/// The rows of the table of variants `name` (see [`tables`]).
fn variants_table<'a>(name: &str, rows: &[&'a Row]) -> Table {
    let (mut variants, mut quantities): (Vec<&str>, Vec<&str>) = (Vec::new(), Vec::new());
    for (i, r) in rows.iter().enumerate() {
        if !variants.contains(&r.variant.as_str()) {
            variants.push(&r.variant);
        }
        if !quantities.contains(&r.quantity.as_str()) {
            // Next to the quantity before it in its variant's rows, so that a quantity only some variants
            // have keeps its place among the others.
            let before = rows[..i].iter().rev().find(|p| p.variant == r.variant);
            match before.and_then(|p| quantities.iter().position(|q| *q == p.quantity)) {
                Some(k) => quantities.insert(k + 1, &r.quantity),
                None => quantities.push(&r.quantity),
            }
        }
    }
    // The rows of a variant and quantity (one, unless an experiment wrote the same figure twice).
    let cell = |variant: &'a str, quantity: &'a str| {
        rows.iter().filter(move |r| r.variant == variant && r.quantity == quantity)
    };
    // Each quantity's published figure where every variant has the same.
    let shared: Vec<Option<&str>> = quantities
        .iter()
        .map(|&q| {
            let mut published = rows.iter().filter(|r| r.quantity == q).map(|r| r.published.as_str());
            let first = published.next().unwrap_or_default();
            published.all(|p| p == first).then_some(first)
        })
        .collect();
    let column = shared.contains(&None);
    let mut header: Vec<String> = std::iter::once(name).chain(quantities.iter().copied()).map(String::from).collect();
    if column {
        header.push("published".into());
    }
    let mut lines = Vec::new();
    for &v in &variants {
        let mut cells = vec![v.to_string()];
        for &q in &quantities {
            let ours: Vec<&str> = cell(v, q).map(|r| r.ours.as_str()).collect();
            cells.push(if ours.is_empty() { NONE.to_string() } else { ours.join("; ") });
        }
        if column {
            let own: Vec<(&str, &str)> = quantities
                .iter()
                .zip(&shared)
                .filter(|(_, s)| s.is_none())
                .flat_map(|(&q, _)| cell(v, q).map(move |r| (q, r.published.as_str())))
                .filter(|(_, p)| !p.is_empty())
                .collect();
            cells.push(match own.as_slice() {
                [] => NONE.to_string(),
                [(_, p), rest @ ..] if rest.iter().all(|(_, o)| o == p) => p.to_string(),
                _ => own.iter().map(|(q, p)| format!("{q}: {p}")).collect::<Vec<_>>().join("; "),
            });
        }
        lines.push(cells);
    }
    if shared.iter().any(|p| p.is_some_and(|p| !p.is_empty())) {
        let mut cells = vec!["published".to_string()];
        cells.extend(shared.iter().map(|p| or_none(p.unwrap_or_default())));
        if column {
            cells.push(String::new());
        }
        lines.push(cells);
    }
    Table { header, lines }
}

/// The headline summary's table: one line per published figure (ours, published, verdict).
fn summary_table(results: &[ExperimentResult]) -> Table {
    Table {
        header: ["figure", "augsim", "published", "augsim is"].map(String::from).to_vec(),
        lines: results
            .iter()
            .flat_map(|r| &r.headlines)
            .map(|h| vec![h.figure.clone(), h.ours.clone(), h.published.clone(), h.verdict.word().to_string()])
            .collect(),
    }
}

/// The headline summary: one row per published figure (ours, published, verdict).
pub fn summary(results: &[ExperimentResult]) -> String {
    let mut s = summary_table(results).markdown();
    let sizes: Vec<String> = results.iter().map(|r| format!("{} {}", r.name.as_str(), r.size.as_str())).collect();
    let _ = write!(
        s,
        "\nFrom `augsim experiment` ({}); \"on par\": within {:.0} %. Every figure is measured on data that played \
         no part in producing it.\n",
        sizes.join(", "),
        100.0 * crate::ON_PAR
    );
    s
}

/// The Markdown report; figure paths are relative to `root`.
pub fn markdown(results: &[ExperimentResult]) -> String {
    let mut s = String::from("# augsim experiments\n\n## Summary\n\n");
    s.push_str(&summary(results));
    s.push_str(&sections(results, "##", true));
    s
}

/// The results page (`docs/results.md`): the summary, then every experiment's table and notes.
pub fn results_page(results: &[ExperimentResult]) -> String {
    let mut s = String::from(PAGE_TITLE);
    s.push_str(
        "\nGenerated by `augsim experiment all --readme README.md --results docs/results.md` from the \
         experiments' `result.json` files; do not edit by hand. The same tables, with their figures (learning \
         curves, error histograms, filter traces, TRE bars), are in `out/experiments/report.html` after a run.\n\n\
         ## Summary\n\n",
    );
    s.push_str(&summary(results));
    let _ = writeln!(s, "\n{SOURCES}");
    s.push_str("\n## Details\n");
    s.push_str(&sections(results, "###", false));
    s
}

/// One section per result under `heading` (e.g. `##`), with or without the figures.
fn sections(results: &[ExperimentResult], heading: &str, figures: bool) -> String {
    let mut s = String::new();
    for r in results {
        let _ = write!(s, "\n{heading} {}\n\n", r.name.title());
        let _ =
            writeln!(s, "`augsim experiment {} --size {}` ({:.0} s)\n", r.name.as_str(), r.size.as_str(), r.seconds);
        for table in tables(&r.rows) {
            s.push_str(&table.markdown());
            s.push('\n');
        }
        for note in &r.notes {
            let _ = writeln!(s, "- {note}");
        }
        if !figures && !r.page_figures.is_empty() {
            s.push('\n');
            for f in &r.page_figures {
                let _ = writeln!(s, "![{f}]({})", page_figure(r, f));
            }
        }
        if figures && !r.figures.is_empty() {
            s.push('\n');
            for f in &r.figures {
                if f.ends_with(".html") {
                    let _ = writeln!(s, "[3D viewer: {f}]({}/{f})", r.name.as_str());
                } else {
                    let _ = writeln!(s, "![{f}]({}/{f})", r.name.as_str());
                }
            }
        }
    }
    s
}

/// Start and end markers of the generated part of a Markdown file (e.g. the README).
pub const MARKERS: [&str; 2] = ["<!-- augsim experiment: begin -->", "<!-- augsim experiment: end -->"];

/// The text of the Markdown file at `path` and where its summary's markers begin.
fn marked(path: &Path) -> Result<(String, usize, usize)> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let (Some(begin), Some(end)) = (text.find(MARKERS[0]), text.find(MARKERS[1])) else {
        bail!("{} has no '{}' … '{}' markers", path.display(), MARKERS[0], MARKERS[1]);
    };
    if let Some(twice) = MARKERS.iter().find(|m| text.matches(*m).count() > 1) {
        bail!(
            "{} holds '{twice}' more than once (one in its text?): the summary would replace what lies between the \
             wrong ones; keep one of each marker",
            path.display()
        );
    }
    if end < begin {
        bail!("{}: the end marker comes before the begin marker", path.display());
    }
    Ok((text, begin, end))
}

/// Refuses, before any experiment runs, a `readme` that [`publish`] could not update (unreadable,
/// or without its markers) and a results `page` that is a folder.
pub fn check_publish_paths(readme: Option<&Path>, page: Option<&Path>) -> Result<()> {
    for path in readme.iter().chain(&page).filter(|p| p.exists()) {
        if std::fs::metadata(path).is_ok_and(|m| m.permissions().readonly()) {
            bail!("{} is read-only: it would be rewritten all the same; make it writable first", path.display());
        }
    }
    if let Some(readme) = readme {
        marked(readme)?;
    }
    let Some(page) = page else { return Ok(()) };
    if page.is_dir() {
        bail!("the results page {} is a folder, not a file", page.display());
    }
    if readme.is_some_and(|r| mesh::io::file_key(r) == mesh::io::file_key(page)) {
        bail!("--readme and --results name one file, {}: the page would replace the README", page.display());
    }
    if page.exists() {
        let text = std::fs::read_to_string(page).with_context(|| format!("reading {}", page.display()))?;
        if !text.starts_with(PAGE_TITLE) {
            bail!(
                "{} is not a results page augsim wrote (its first line is not '{}'): it would be replaced whole; \
                 give another --results",
                page.display(),
                PAGE_TITLE.trim()
            );
        }
    }
    mesh::io::check_writable(page).context("the results page could not be written there")?;
    Ok(())
}

/// The first line of a results page ([`results_page`]).
const PAGE_TITLE: &str = "# Results\n";

/// The experiments (and sizes, as `liver-ar paper`) that the summary in `text` lists, from its
/// "From `augsim experiment` (…)" line; empty when it has none.
fn summarised(text: &str) -> Vec<String> {
    let lead = "From `augsim experiment` (";
    let Some(from) = text.find(lead).map(|at| at + lead.len()) else { return Vec::new() };
    let listed = text[from..].split(')').next().unwrap_or_default();
    listed.split(", ").map(str::to_string).collect()
}

/// Refuses to rewrite the summary of `path` (its text `text`) with `results` where they would drop
/// an experiment it lists, or replace a paper result by a quick one: a partial `--out` would
/// silently unpublish the others.
fn check_keeps_published(path: &Path, text: &str, results: &[ExperimentResult]) -> Result<()> {
    let kept = |old: &String| {
        let (name, size) = old.split_once(' ').unwrap_or((old, ""));
        let new = results.iter().find(|r| r.name.as_str() == name);
        new.is_some_and(|r| r.size == Size::Paper || size != Size::Paper.as_str())
    };
    let lost: Vec<String> = summarised(text).into_iter().filter(|old| !kept(old)).collect();
    if !lost.is_empty() {
        bail!(
            "{} shows results that --out does not hold at their size ({}): the new summary would drop them; give \
             the --out that holds them all (or empty its summary first to publish these alone)",
            path.display(),
            lost.join(", ")
        );
    }
    Ok(())
}

/// Replaces the text between the [`MARKERS`] of the Markdown file `path` (e.g. the README) with
/// the results' [`summary`], atomically.
pub fn update_markdown(path: &Path, results: &[ExperimentResult]) -> Result<()> {
    let (text, begin, end) = marked(path)?;
    check_keeps_published(path, &text[begin..end], results)?;
    let head = &text[..begin + MARKERS[0].len()];
    let updated = format!("{head}\n{}\n{}", summary(results).trim(), &text[end..]);
    mesh::io::write_atomic_bytes(&written_through(path), updated.as_bytes())?;
    Ok(())
}

/// The file a write to `path` should replace: the target of a symbolic link (not the link).
fn written_through(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

/// The HTML report (no script, no external resource); figure paths are relative to `root`.
pub fn html(results: &[ExperimentResult]) -> String {
    let mut s = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>augsim experiments</title>\n<style>\
         body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}\
         table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:4px 10px;text-align:left}\
         th{background:#f2f2f2}img{max-width:48%;margin:4px;border:1px solid #eee}code{background:#f6f6f6}\
         </style></head><body>\n<h1>augsim experiments</h1>\n<p>Each table puts our figure beside the published one; \
         every test figure is measured on data that played no part in producing it (rows of design cases and \
         validation curves, which chose settings, say so).</p>\n<h2>Summary</h2>\n",
    );
    s.push_str(&summary_table(results).html());
    for r in results {
        let _ = writeln!(
            s,
            "<h2>{}</h2>\n<p><code>augsim experiment {} --size {}</code> ({:.0} s)</p>",
            escape_html(r.name.title()),
            r.name.as_str(),
            r.size.as_str(),
            r.seconds
        );
        for table in tables(&r.rows) {
            s.push_str(&table.html());
        }
        s.push_str("<ul>\n");
        for note in &r.notes {
            let _ = writeln!(s, "<li>{}</li>", escape_html(note));
        }
        s.push_str("</ul>\n<div>\n");
        for f in &r.figures {
            let src = format!("{}/{f}", r.name.as_str());
            if f.ends_with(".html") {
                let _ = writeln!(
                    s,
                    "<p><a href=\"{0}\">3D viewer ({0})</a>: rotate the organ, errors as colour</p>",
                    escape_html(&src)
                );
            } else {
                let _ = writeln!(s, "<a href=\"{0}\"><img src=\"{0}\" alt=\"{0}\"></a>", escape_html(&src));
            }
        }
        s.push_str("</div>\n");
    }
    s.push_str("</body></html>\n");
    s
}

/// Writes the results page [`results_page`] to `path`, atomically, with copies of the results'
/// page figures (from `root/<experiment>/`) beside it.
pub fn write_results_page(path: &Path, results: &[ExperimentResult], root: &Path) -> Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    mesh::io::create_folder(dir)?;
    for r in results {
        for f in &r.page_figures {
            let (from, to) = (root.join(r.name.as_str()).join(f), dir.join(page_figure(r, f)));
            let bytes = std::fs::read(&from).with_context(|| format!("reading {}", from.display()))?;
            mesh::io::write_atomic_bytes(&to, &bytes)?;
        }
    }
    mesh::io::write_atomic_bytes(&written_through(path), results_page(results).as_bytes())?;
    Ok(())
}

/// The results page's copy of figure `f` of result `r`: `<experiment>-<file name>`.
fn page_figure(r: &ExperimentResult, f: &str) -> String {
    let file = Path::new(f).file_name().map_or(f.into(), |n| n.to_string_lossy().into_owned());
    format!("{}-{file}", r.name.as_str())
}

/// Writes `root/report.md` and `root/report.html`; returns their paths.
pub fn write(root: &Path, results: &[ExperimentResult]) -> Result<[PathBuf; 2]> {
    let md = root.join("report.md");
    let page = root.join("report.html");
    mesh::io::write_atomic_bytes(&md, markdown(results).as_bytes())?;
    mesh::io::write_atomic_bytes(&page, html(results).as_bytes())?;
    Ok([md, page])
}

/// The reports of every result under `root` ([`crate::load_all`]): `report.md` and `report.html`
/// there ([`write()`]), and, when given, the headline summary of the Markdown file `readme`
/// ([`update_markdown`]) and the full results page `page` ([`write_results_page`]); what was
/// written, a line each.
pub fn publish(root: &Path, readme: Option<&Path>, page: Option<&Path>) -> Result<Vec<String>> {
    let results = crate::load_all(root)?;
    // Nothing is published where the page would drop what it shows (the README checks itself).
    if let Some((page, text)) = page.and_then(|p| Some((p, std::fs::read_to_string(p).ok()?))) {
        check_keeps_published(page, &text, &results)?;
    }
    let [md, html] = write(root, &results)?;
    let mut lines = vec![format!("wrote      {} and {} ({} experiments)", md.display(), html.display(), results.len())];
    let older: Vec<String> = results
        .iter()
        .filter(|r| r.build != crate::BUILD)
        .map(|r| format!("{} ({})", r.name.as_str(), if r.build.is_empty() { "unnamed" } else { &r.build }))
        .collect();
    if !older.is_empty() {
        lines.push(format!(
            "warning    {} of them made by another build than this one ({}): published as they are, each with \
             its date in its notes",
            older.join(", "),
            crate::BUILD
        ));
    }
    if let Some(readme) = readme {
        update_markdown(readme, &results)?;
        lines.push(format!("updated    {}", readme.display()));
    }
    if let Some(page) = page {
        write_results_page(page, &results, root)?;
        lines.push(format!("wrote      {}", page.display()));
    }
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Name, Row};

    fn markdown(rows: &[Row]) -> String {
        tables(rows).iter().map(Table::markdown).collect::<Vec<_>>().join("\n")
    }

    /// Rows without a variant stay a table of quantities; the rows of a table of variants become one
    /// line per variant and one column per quantity, with the published figures they share on a last
    /// line, a quantity only some variants have in its place and "—" where a variant has none.
    #[test]
    fn variants_become_lines_and_quantities_columns() {
        let run = |variant: &str, e: &str, sigma: Option<&str>| {
            let mut rows = vec![Row::new("estimated E", e, "4,992 ± 15 Pa")];
            rows.extend(sigma.map(|s| Row::new("noise-only σ", s, "")));
            rows.push(Row::new("filter time", "2.4 s", "500 s"));
            rows.into_iter().map(|r| r.of("filter run", variant)).collect::<Vec<_>>()
        };
        let rows: Vec<Row> = std::iter::once(Row::new("truth", "5000 Pa", ""))
            .chain(run("scenario", "4458 ± 7 Pa", None))
            .chain(run("11k model", "4811 ± 350 Pa", Some("6 Pa")))
            .chain([Row::new("|error| / σ", "0.5", "a | b")])
            .collect();
        let expected = "\
| quantity | augsim | published |
| --- | --- | --- |
| truth | 5000 Pa | — |
| \\|error\\| / σ | 0.5 | a \\| b |

| filter run | estimated E | noise-only σ | filter time |
| --- | --- | --- | --- |
| scenario | 4458 ± 7 Pa | — | 2.4 s |
| 11k model | 4811 ± 350 Pa | 6 Pa | 2.4 s |
| published | 4,992 ± 15 Pa | — | 500 s |
";
        assert_eq!(markdown(&rows), expected);
    }

    /// A quantity whose published figure differs between variants moves it into a last column,
    /// one per variant; without any published figure there is neither that column nor the line.
    #[test]
    fn published_figures_that_differ_go_in_a_column() {
        let rows = vec![
            Row::new("first", "18.4 ms", "1,550 ms (SVK)").of("case", "liver, SVK"),
            Row::new("frame", "2.6 ms", "").of("case", "liver, SVK"),
            Row::new("first", "19.9 ms", "25 ms (co-rotational)").of("case", "liver, co-rotational"),
            Row::new("frame", "3.4 ms", "").of("case", "liver, co-rotational"),
            Row::new("first", "617.1 ms", "").of("case", "liver T10, SVK"),
            Row::new("frame", "68.5 ms", "").of("case", "liver T10, SVK"),
            Row::new("first", "1.24×", "").of("F-bar / standard", "beam"),
        ];
        let expected = "\
| case | first | frame | published |
| --- | --- | --- | --- |
| liver, SVK | 18.4 ms | 2.6 ms | 1,550 ms (SVK) |
| liver, co-rotational | 19.9 ms | 3.4 ms | 25 ms (co-rotational) |
| liver T10, SVK | 617.1 ms | 68.5 ms | — |

| F-bar / standard | first |
| --- | --- |
| beam | 1.24× |
";
        assert_eq!(markdown(&rows), expected);
    }

    /// The results page and the HTML report show the same tables: a section's tables one after the
    /// other, then its notes.
    #[test]
    fn every_report_shows_the_tables_of_variants() {
        let result = ExperimentResult {
            name: Name::Young,
            size: Size::Quick,
            seconds: 61.0,
            build: "0123456789ab".into(),
            headlines: Vec::new(),
            rows: vec![
                Row::new("filter time", "2.4 s", "500 s").of("filter run", "scenario"),
                Row::new("filter time", "5.8 s", "500 s").of("filter run", "11k model"),
                Row::new("truth", "5000 Pa", ""),
            ],
            figures: Vec::new(),
            page_figures: Vec::new(),
            notes: vec!["A note.".into()],
            values: serde_json::Map::new(),
        };
        let page = results_page(std::slice::from_ref(&result));
        let section = "`augsim experiment young --size quick` (61 s)\n\n\
                       | filter run | filter time |\n| --- | --- |\n| scenario | 2.4 s |\n| 11k model | 5.8 s |\n\
                       | published | 500 s |\n\n| quantity | augsim | published |\n| --- | --- | --- |\n\
                       | truth | 5000 Pa | — |\n\n- A note.\n";
        assert!(page.ends_with(section), "{page}");
        let html = html(std::slice::from_ref(&result));
        assert!(html.contains(
            "<table><tr><th>filter run</th><th>filter time</th></tr>\n<tr><td>scenario</td><td>2.4 s</td></tr>\n\
             <tr><td>11k model</td><td>5.8 s</td></tr>\n<tr><td>published</td><td>500 s</td></tr>\n</table>\n"
        ));
    }
}
