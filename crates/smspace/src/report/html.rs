//! `report.html`: one self-contained file that works offline.
//!
//! Everything is inline: the figures (PNG as `data:` URLs, or the SVG text), the
//! numbers, and an interactive view of the embedding drawn by plotly.js, whose source
//! (`assets/plotly-2.12.1.min.js`) is embedded in the library and written into the
//! page. The page loads nothing from anywhere.
//!
//! For automated checks (`.ci/browser-check`), a script that runs first records
//! `window.onerror`, unhandled rejections and `console.error` calls; once
//! `Plotly.newPlot` has resolved, `<body>` carries `data-plot-status="drawn"`,
//! `data-errors` (the number of recorded errors) and `data-webgl` (`yes` when a WebGL
//! canvas of non-zero size exists in the plot's `<div>`).

use base64::Engine;
use serde_json::{json, Value};

use super::plot::Rendered;
use super::tables::{num, Table};
use super::{FigureRecord, ReportInputs};

/// plotly.js, MIT licence (see `assets/README.md`).
static PLOTLY_JS: &str = include_str!("../../assets/plotly-2.12.1.min.js");

/// Escapes text for HTML content and attribute values.
pub(super) fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
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

/// JSON that is safe inside a `<script>` element: no `<` (so no `</script>` or
/// `<!--`) and no line separators that old parsers reject.
fn script_json(value: &Value) -> String {
    serde_json::to_string(value)
        .unwrap_or_else(|_| "null".to_owned())
        .replace('<', "\\u003c")
        .replace('\u{2028}', "\\u2028")
        .replace('\u{2029}', "\\u2029")
}

const HEAD_SCRIPT: &str = r#"<script>
(function () {
  var errors = [];
  window.__reportErrors = errors;
  window.onerror = function (message, source, line) {
    errors.push(String(message) + (line ? " (line " + line + ")" : ""));
  };
  window.addEventListener("unhandledrejection", function (event) {
    errors.push("unhandled rejection: " + String(event.reason));
  });
  var consoleError = console.error;
  console.error = function () {
    errors.push(Array.prototype.map.call(arguments, String).join(" "));
    return consoleError.apply(console, arguments);
  };
  var getContext = HTMLCanvasElement.prototype.getContext;
  HTMLCanvasElement.prototype.getContext = function (type) {
    var context = getContext.apply(this, arguments);
    if (context && /webgl/.test(String(type))) { this.setAttribute("data-webgl-context", String(type)); }
    return context;
  };
})();
</script>"#;

const STYLE: &str = r#"<style>
body { font-family: "DejaVu Sans", Verdana, sans-serif; margin: 2em auto; max-width: 1320px; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { margin-bottom: 0.2em; }
h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 2em; }
table { border-collapse: collapse; margin: 0.8em 0; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.7em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 1.5em 0; }
figure img, figure svg { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 0.95em; color: #444; margin-top: 0.3em; }
.skipped { color: #777; }
pre { background: #f7f7f7; padding: 1em; overflow-x: auto; border: 1px solid #e5e5e5; }
#embedding-view { width: 100%; height: 680px; border: 1px solid #eee; }
nav a { margin-right: 1em; }
</style>"#;

/// The data of the interactive view: coordinates, colour options and hover text.
fn plot_spec(inputs: &ReportInputs<'_>) -> Value {
    let (m, d) = inputs.embedding.dim();
    let mut trace = json!({
        "name": "kernel sets",
        "mode": "markers",
        "text": hover_text(inputs),
        "hovertemplate": "%{text}<extra></extra>",
    });
    let layout_axes = place_points(&mut trace, inputs);
    let marker_size = if d >= 3 { 2.5 } else { 4.0 };
    let (mut buttons, first_marker) = pose_buttons(inputs, marker_size);
    buttons.extend(probe_button(inputs));
    trace["marker"] = first_marker.unwrap_or_else(|| json!({"size": marker_size}));
    let mut layout = json!({
        "margin": {"l": 10, "r": 10, "t": 50, "b": 10},
        "showlegend": false,
        "hovermode": "closest",
        "title": {"text": format!("{} kernel sets, embedding dimension {d}", m)},
        "updatemenus": [{
            "buttons": buttons,
            "direction": "down",
            "showactive": true,
            "x": 0.0,
            "xanchor": "left",
            "y": 1.08,
            "yanchor": "top",
        }],
    });
    if let (Some(l), Some(a)) = (layout.as_object_mut(), layout_axes.as_object()) {
        for (k, v) in a {
            l.insert(k.clone(), v.clone());
        }
    }
    json!({"data": [trace], "layout": layout})
}

/// `v` rounded to six decimals, to keep the page small.
fn round6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// Coordinate `c` (0 = x, 1 = y, 2 = alpha) of the pose of set `i`, when there are
/// planar poses.
fn set_pose(inputs: &ReportInputs<'_>, i: usize, c: usize) -> Option<f64> {
    inputs.poses.map(|poses| poses[[inputs.kept[i], c]])
}

/// The hover text of every set: its exploration row, pose and probe label.
fn hover_text(inputs: &ReportInputs<'_>) -> Vec<String> {
    let m = inputs.embedding.nrows();
    let pose = |i: usize, c: usize| set_pose(inputs, i, c);
    let mut text = Vec::with_capacity(m);
    for i in 0..m {
        let row = inputs.kept[i];
        let label = inputs.probes.row(row);
        let probe = if label[0] >= 0 {
            format!(
                "<br>probe: orientation {}, cell ({}, {})",
                label[0], label[1], label[2]
            )
        } else {
            "<br>babbled".to_owned()
        };
        let pose = match (pose(i, 0), pose(i, 1), pose(i, 2)) {
            (Some(x), Some(y), Some(alpha)) => format!(
                "<br>x = {} m, y = {} m<br>alpha = {} rad ({:.1}°)",
                num(x),
                num(y),
                num(alpha),
                alpha.to_degrees()
            ),
            _ => String::new(),
        };
        text.push(format!("set {i}, exploration row {row}{pose}{probe}"));
    }
    text
}

/// Sets the trace's type and coordinates for the embedding's dimension (a 3-D scatter
/// of the first three coordinates, a 2-D one, or `q1` against the set index) and
/// returns the matching layout axes.
fn place_points(trace: &mut Value, inputs: &ReportInputs<'_>) -> Value {
    let e = inputs.embedding;
    let (m, d) = e.dim();
    let column = |k: usize| -> Vec<f64> { (0..m).map(|i| round6(e[[i, k]])).collect() };
    if d >= 3 {
        trace["type"] = json!("scatter3d");
        trace["x"] = json!(column(0));
        trace["y"] = json!(column(1));
        trace["z"] = json!(column(2));
        json!({
            "scene": {
                "xaxis": {"title": {"text": "q1"}},
                "yaxis": {"title": {"text": "q2"}},
                "zaxis": {"title": {"text": "q3"}},
                "aspectmode": "data",
            }
        })
    } else if d == 2 {
        trace["type"] = json!("scattergl");
        trace["x"] = json!(column(0));
        trace["y"] = json!(column(1));
        json!({
            "xaxis": {"title": {"text": "q1"}},
            "yaxis": {"title": {"text": "q2"}, "scaleanchor": "x"},
        })
    } else {
        trace["type"] = json!("scattergl");
        trace["x"] = json!(if d == 1 { column(0) } else { Vec::new() });
        trace["y"] = json!((0..m).collect::<Vec<_>>());
        json!({
            "xaxis": {"title": {"text": "q1"}},
            "yaxis": {"title": {"text": "set index"}},
        })
    }
}

/// The colour scale of pose coordinate `c` with its range, `(colorscale, cmin,
/// cmax)`: a circular hue scale over `[-π, π]` for alpha, Viridis over the values'
/// range (or a unit range around a constant) for x and y.
fn pose_color_scale(c: usize, values: &[f64]) -> (Value, Value, Value) {
    if c == 2 {
        let hue_scale: Vec<Value> = (0..=12)
            .map(|k| {
                json!([
                    f64::from(k) / 12.0,
                    format!("hsl({}, 75%, 47%)", 30 * k % 360)
                ])
            })
            .collect();
        (
            json!(hue_scale),
            json!(-std::f64::consts::PI),
            json!(std::f64::consts::PI),
        )
    } else {
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let (lo, hi) = if lo.is_finite() && hi > lo {
            (lo, hi)
        } else {
            (lo.min(0.0) - 0.5, lo.max(0.0) + 0.5)
        };
        (json!("Viridis"), json!(lo), json!(hi))
    }
}

/// One menu button per pose coordinate that colours the points by it, and the
/// marker of the first (x), which the view starts with.
fn pose_buttons(inputs: &ReportInputs<'_>, marker_size: f64) -> (Vec<Value>, Option<Value>) {
    let m = inputs.embedding.nrows();
    let mut buttons = Vec::new();
    let mut first_marker = None;
    for (c, (name, unit)) in [("x", "m"), ("y", "m"), ("alpha", "rad")]
        .into_iter()
        .enumerate()
    {
        let Some(values) = (0..m)
            .map(|i| set_pose(inputs, i, c).map(round6))
            .collect::<Option<Vec<f64>>>()
        else {
            // No planar poses: no colouring by pose.
            break;
        };
        let (colorscale, cmin, cmax) = pose_color_scale(c, &values);
        let title = format!("{name} ({unit})");
        if first_marker.is_none() {
            first_marker = Some(json!({
                "size": marker_size,
                "color": values.clone(),
                "colorscale": colorscale.clone(),
                "cmin": cmin.clone(),
                "cmax": cmax.clone(),
                "showscale": true,
                "colorbar": {"title": {"text": title.clone()}},
            }));
        }
        buttons.push(json!({
            "label": format!("colour by {name}"),
            "method": "restyle",
            "args": [{
                "marker.color": [values],
                "marker.colorscale": [colorscale],
                "marker.cmin": [cmin],
                "marker.cmax": [cmax],
                "marker.showscale": [true],
                "marker.colorbar.title.text": [title],
            }],
        }));
    }
    (buttons, first_marker)
}

/// The menu button that colours the probe sets by orientation (babbled sets in
/// faint grey), when there are probe sets.
fn probe_button(inputs: &ReportInputs<'_>) -> Option<Value> {
    let m = inputs.embedding.nrows();
    let orientation = |i: usize| inputs.probes[[inputs.kept[i], 0]];
    if !(0..m).any(|i| orientation(i) >= 0) {
        return None;
    }
    let orientations = (0..m).map(orientation).max().unwrap_or(0) + 1;
    let colors: Vec<String> = (0..m)
        .map(|i| {
            let o = orientation(i);
            if o < 0 {
                "rgba(160,160,160,0.35)".to_owned()
            } else {
                format!("hsl({}, 75%, 45%)", 360 * o / orientations)
            }
        })
        .collect();
    Some(json!({
        "label": "probe surfaces (orientation)",
        "method": "restyle",
        "args": [{
            "marker.color": [colors],
            "marker.showscale": [false],
        }],
    }))
}

const PLOT_SCRIPT: &str = r#"<script>
(function () {
  var body = document.body;
  var div = document.getElementById("embedding-view");
  var spec = JSON.parse(document.getElementById("embedding-data").textContent);
  function finish(status) {
    body.setAttribute("data-plot-status", status);
    var found = "no", size = "0x0";
    var canvases = div.querySelectorAll("canvas[data-webgl-context]");
    for (var i = 0; i < canvases.length; i++) {
      var c = canvases[i];
      if (c.width > 0 && c.height > 0) { found = "yes"; size = c.width + "x" + c.height; break; }
    }
    body.setAttribute("data-webgl", found);
    body.setAttribute("data-webgl-size", size);
    body.setAttribute("data-errors", String(window.__reportErrors.length));
    if (window.__reportErrors.length > 0) {
      body.setAttribute("data-error-list", window.__reportErrors.join(" | ").slice(0, 2000));
    }
  }
  try {
    Plotly.newPlot(div, spec.data, spec.layout, {responsive: true, displaylogo: false})
      .then(function () { finish("drawn"); })
      .catch(function (error) { window.__reportErrors.push(String(error)); finish("failed"); });
  } catch (error) {
    window.__reportErrors.push(String(error));
    finish("failed");
  }
})();
</script>"#;

fn table_html(t: &Table, out: &mut String) {
    out.push_str(&format!("<h3>{}</h3>\n<table>\n<tr>", escape(&t.title)));
    for h in &t.header {
        out.push_str(&format!("<th>{}</th>", escape(h)));
    }
    out.push_str("</tr>\n");
    for row in &t.rows {
        out.push_str("<tr>");
        for (k, cell) in row.iter().enumerate() {
            let numeric = k > 0 && cell.parse::<f64>().is_ok();
            out.push_str(&format!(
                "<td{}>{}</td>",
                if numeric { " class=\"num\"" } else { "" },
                escape(cell)
            ));
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</table>\n");
    if let Some(note) = &t.note {
        out.push_str(&format!("<p>{}</p>\n", escape(note)));
    }
}

/// Removes the XML declaration of an SVG document so that it can be inlined.
fn inline_svg(svg: &str) -> &str {
    match svg.find("<svg") {
        Some(start) => &svg[start..],
        None => svg,
    }
}

/// The whole page.
pub(super) fn html(
    inputs: &ReportInputs<'_>,
    tables: &[Table],
    figures: &[(FigureRecord, Rendered)],
) -> String {
    let mut out = String::with_capacity(PLOTLY_JS.len() + (1 << 20));
    out.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    out.push_str(HEAD_SCRIPT);
    out.push_str(&format!(
        "\n<title>{}</title>\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n",
        escape(inputs.name)
    ));
    out.push_str(STYLE);
    out.push_str("\n</head>\n<body data-plot-status=\"pending\">\n");
    out.push_str(&format!(
        "<h1>{}</h1>\n<p>{}</p>\n",
        escape(inputs.name),
        escape(inputs.description)
    ));
    out.push_str(&format!(
        "<p>Agent <b>{}</b>: {} motors, {} sensors; {} environment(s); {} explored configurations, {} kernel sets of {} points, embedding dimension {}.</p>\n",
        escape(inputs.agent.name()),
        inputs.agent.motor_dim(),
        inputs.agent.sensor_dim(),
        inputs.environments.len(),
        inputs.motors.nrows(),
        inputs.sets.len_of(ndarray::Axis(0)),
        inputs.sets.len_of(ndarray::Axis(1)),
        inputs.embedding.ncols()
    ));
    out.push_str("<nav><a href=\"#view\">interactive view</a><a href=\"#numbers\">numbers</a><a href=\"#figures\">figures</a><a href=\"#config\">configuration</a></nav>\n");

    out.push_str("<h2 id=\"view\">Interactive view of the embedding</h2>\n");
    out.push_str("<p>Drag to rotate, scroll to zoom; the menu colours the points by a pose coordinate or by probe orientation; hovering a point shows its set, exploration row and pose.</p>\n");
    out.push_str("<div id=\"embedding-view\"></div>\n");

    out.push_str("<h2 id=\"numbers\">Numbers</h2>\n");
    for t in tables {
        table_html(t, &mut out);
    }

    out.push_str("<h2 id=\"figures\">Figures</h2>\n");
    for (record, rendered) in figures {
        let id = escape(&record.name);
        if let Some(reason) = &record.skipped {
            out.push_str(&format!(
                "<p class=\"skipped\" id=\"{id}\"><b>{id}</b> skipped: {}</p>\n",
                escape(reason)
            ));
            continue;
        }
        out.push_str(&format!("<figure id=\"{id}\">\n"));
        if let Some(png) = &rendered.png {
            out.push_str(&format!(
                "<img alt=\"{}\" src=\"data:image/png;base64,{}\">\n",
                escape(&record.caption),
                base64::engine::general_purpose::STANDARD.encode(png)
            ));
        } else if let Some(svg) = &rendered.svg {
            out.push_str(inline_svg(svg));
            out.push('\n');
        }
        out.push_str(&format!(
            "<figcaption><b>{id}</b>: {}</figcaption>\n</figure>\n",
            escape(&record.caption)
        ));
    }

    out.push_str("<h2 id=\"config\">Configuration</h2>\n<pre>");
    out.push_str(&escape(inputs.config_toml));
    out.push_str("</pre>\n");

    out.push_str("<script id=\"embedding-data\" type=\"application/json\">");
    out.push_str(&script_json(&plot_spec(inputs)));
    out.push_str("</script>\n<script>\n");
    out.push_str(PLOTLY_JS);
    out.push_str("\n</script>\n");
    out.push_str(PLOT_SCRIPT);
    out.push_str("\n</body>\n</html>\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escaping_covers_markup_and_scripts() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
        let v = json!({"t": "</script><!--"});
        let s = script_json(&v);
        assert!(!s.contains('<'));
        assert_eq!(serde_json::from_str::<Value>(&s).unwrap(), v);
    }

    #[test]
    fn plotly_source_is_embedded_and_has_no_closing_script_tag() {
        assert!(PLOTLY_JS.len() > 1_000_000);
        assert!(!PLOTLY_JS.contains("</script"));
        assert!(PLOTLY_JS.contains("plotly.js v2.12.1"));
    }
}
