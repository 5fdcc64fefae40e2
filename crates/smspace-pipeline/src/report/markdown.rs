//! `report.md`: the numbers as Markdown tables and links to the figures, readable in a
//! terminal.

use super::html::{overview, skipped_sentence};
use super::tables::Table;
use super::{FigureRecord, ReportInputs, Warning};

/// A table cell: `|` escaped, line breaks turned into spaces.
fn cell(text: &str) -> String {
    text.replace('|', "\\|").replace(['\n', '\r'], " ")
}

fn table_markdown(t: &Table, out: &mut String) {
    out.push_str(&format!("### {}\n\n", cell(&t.title)));
    let widths: Vec<usize> = (0..t.header.len())
        .map(|k| {
            std::iter::once(&t.header[k])
                .chain(t.rows.iter().filter_map(|r| r.get(k)))
                .map(|s| cell(s).chars().count())
                .max()
                .unwrap_or(3)
                .max(3)
        })
        .collect();
    let line = |cells: &[String]| {
        let mut s = String::from("|");
        for (k, w) in widths.iter().enumerate() {
            let c = cells.get(k).map(|c| cell(c)).unwrap_or_default();
            let pad = w - c.chars().count().min(*w);
            s.push_str(&format!(" {c}{} |", " ".repeat(pad)));
        }
        s.push('\n');
        s
    };
    out.push_str(&line(&t.header));
    out.push('|');
    for w in &widths {
        out.push_str(&format!("{}|", "-".repeat(w + 2)));
    }
    out.push('\n');
    for row in &t.rows {
        out.push_str(&line(row));
    }
    out.push('\n');
    if let Some(note) = &t.note {
        out.push_str(&format!("{note}\n\n"));
    }
}

/// A code fence longer than any run of backticks in `text`.
fn fence(text: &str) -> String {
    let mut longest = 0;
    let mut run = 0;
    for c in text.chars() {
        if c == '`' {
            run += 1;
            longest = longest.max(run);
        } else {
            run = 0;
        }
    }
    "`".repeat((longest + 1).max(3))
}

/// The whole document.
pub(super) fn markdown(
    inputs: &ReportInputs<'_>,
    tables: &[Table],
    figures: &[FigureRecord],
    warnings: &[Warning],
) -> String {
    let mut out = String::new();
    out.push_str(&format!("# {}\n\n{}\n\n", inputs.name, inputs.description));
    out.push_str(&format!(
        "Agent **{}**: {} The interactive 3-D view is in `report.html`.\n\n",
        inputs.agent.name(),
        overview(inputs)
    ));
    if !warnings.is_empty() {
        out.push_str("## Warnings\n\n");
        for w in warnings {
            out.push_str(&format!("- **{}**: {}\n", w.stage, w.message));
        }
        out.push('\n');
    }
    out.push_str("## Numbers\n\n");
    for t in tables {
        table_markdown(t, &mut out);
    }
    out.push_str("## Figures\n\n");
    if let Some(sentence) = skipped_sentence(inputs, figures.iter()) {
        out.push_str(&format!("{sentence}\n\n"));
    }
    for f in figures.iter().filter(|f| f.skipped.is_none()) {
        let link = f
            .files
            .iter()
            .find(|p| p.extension().is_some_and(|e| e == "png"))
            .or_else(|| f.files.first());
        if let Some(path) = link {
            let path = path.to_string_lossy().replace('\\', "/");
            out.push_str(&format!(
                "### {}\n\n![{}]({path})\n\n{}\n\n",
                f.name,
                f.caption.replace(['[', ']'], ""),
                f.caption
            ));
        }
    }
    let fence = fence(inputs.config_toml);
    out.push_str(&format!(
        "## Configuration\n\n{fence}toml\n{}\n{fence}\n",
        inputs.config_toml.trim_end()
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_are_aligned_and_escaped() {
        let t = Table {
            title: "T".to_owned(),
            header: vec!["a".to_owned(), "b".to_owned()],
            rows: vec![vec!["x|y".to_owned(), "1".to_owned()]],
            note: None,
        };
        let mut s = String::new();
        table_markdown(&t, &mut s);
        assert!(s.contains("| x\\|y | 1   |"), "{s}");
        assert_eq!(fence("a ``` b"), "````");
    }
}
