//! `report.html`: the run's report, which works offline.
//!
//! The page holds the warnings, the numbers, the figures and an interactive view of
//! the embedding drawn by plotly.js, whose source (`assets/plotly-2.12.1.min.js`) is
//! embedded in the library. By default the page loads plotly.js from
//! `assets/plotly-2.12.1.min.js` and the figures from `figures/`, next to it in the run
//! folder (the library is written there with the report, atomically: 3.6 MB per run
//! folder instead of inside every page); a self-contained page inlines both (PNG as `data:`
//! URLs, or the SVG text). Either way it loads nothing from any other place.
//!
//! **Without WebGL** (a headless browser with no GPU, a remote desktop) plotly.js
//! cannot draw the 3-D view. The page therefore shows a static figure of the same
//! embedding by default (Fig. 5d, seen along the ring's axis, or the embedding coloured
//! by pose) and replaces it by the interactive view only once a WebGL context can be
//! created; otherwise `<body>` gets `data-plot-status="static"` and `data-webgl="no"`.
//! The interactive view starts as the static one does: coloured by alpha, seen along
//! the ring's axis.
//!
//! Figures are shown at their print size (1.25 CSS inches per inch of print), so that
//! their 9-point text reads at about the size of the captions; the configuration block
//! wraps its long lines instead of running off the page.
//!
//! For automated checks (`.ci/browser-check`), a script that runs first records
//! `window.onerror`, unhandled rejections and `console.error` calls; once
//! `Plotly.newPlot` has resolved, `<body>` carries `data-plot-status="drawn"`,
//! `data-errors` (the number of recorded errors) and `data-webgl` (`yes` when a WebGL
//! canvas of non-zero size exists in the plot's `<div>`).

use std::path::PathBuf;

use base64::Engine;
use serde_json::{json, Value};

use super::plot::Rendered;
use super::tables::{num, Table};
use super::{FigureRecord, ReportInputs, Warning};

/// plotly.js, MIT licence (see `assets/README.md`).
static PLOTLY_JS: &str = include_str!("../../assets/plotly-2.12.1.min.js");

/// Where a linked page finds plotly.js, relative to the report folder.
const PLOTLY_PATH: &str = "assets/plotly-2.12.1.min.js";

/// plotly.js as a file of the report: its path relative to the report folder and its
/// bytes (staged with the report's other files, so written atomically and hashed like
/// them).
pub(super) fn plotly_file() -> (PathBuf, Vec<u8>) {
    (PathBuf::from(PLOTLY_PATH), PLOTLY_JS.as_bytes().to_vec())
}

/// `n thing` or `n things`.
pub(super) fn count(n: usize, thing: &str) -> String {
    format!("{n} {thing}{}", if n == 1 { "" } else { "s" })
}

/// The sentence that says which figures were not drawn (their reasons are in
/// `report.json`; without planar poses it says that this is why the figures of poses
/// are missing), or `None` when every figure was drawn.
pub(super) fn skipped_sentence<'r>(
    inputs: &ReportInputs<'_>,
    records: impl Iterator<Item = &'r FigureRecord>,
) -> Option<String> {
    let names: Vec<&str> = records
        .filter(|r| r.skipped.is_some())
        .map(|r| r.name.as_str())
        .collect();
    let why = if inputs.poses.is_none() {
        "report.json says why; the agent has no planar ground truth (x, y, alpha), so none of the figures of poses is drawn"
    } else {
        "report.json says why"
    };
    match names.as_slice() {
        [] => None,
        [one] => Some(format!(
            "The figure {one} does not apply to this run ({why})."
        )),
        [rest @ .., last] => Some(format!(
            "The figures {} and {last} do not apply to this run ({why}).",
            rest.join(", ")
        )),
    }
}

/// One sentence on the agent and the data: `Agent X: 1 motor, 2 sensors; …`.
pub(super) fn overview(inputs: &ReportInputs<'_>) -> String {
    format!(
        "{}, {}; {}; {}, {} of {}, embedding dimension {}.",
        count(inputs.agent.motor_dim(), "motor"),
        count(inputs.agent.sensor_dim(), "sensor"),
        count(inputs.environments.len(), "environment"),
        count(inputs.motors.nrows(), "explored configuration"),
        count(inputs.sets.len_of(ndarray::Axis(0)), "kernel set"),
        count(inputs.sets.len_of(ndarray::Axis(1)), "point"),
        inputs.embedding.ncols()
    )
}

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

/// The page style of the reports (and of the comparison page, [`super::compare`]).
pub(super) const STYLE: &str = r#"<style>
body { font-family: "DejaVu Sans", Verdana, sans-serif; margin: 2em auto; max-width: 1320px; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { margin-bottom: 0.2em; }
h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 2em; }
table { border-collapse: collapse; margin: 0.8em 0; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.7em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 1.5em 0; }
figure img, figure svg { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 1em; color: #333; margin-top: 0.4em; max-width: 52em; }
.skipped { color: #555; }
.warnings { border: 1px solid #d9a400; background: #fff8e1; padding: 0.4em 1em; }
.warnings li { margin: 0.3em 0; }
table { max-width: 100%; }
td { overflow-wrap: anywhere; }
pre { background: #f7f7f7; padding: 1em; border: 1px solid #e5e5e5; max-width: 100%; box-sizing: border-box; white-space: pre-wrap; overflow-wrap: anywhere; overflow-x: auto; }
#embedding-view { width: 100%; height: 680px; border: 1px solid #eee; }
#embedding-view[hidden], #embedding-static[hidden] { display: none; }
nav a { margin-right: 1em; }
</style>"#;

/// The data of the interactive view: coordinates, colour options and hover text.
fn plot_spec(inputs: &ReportInputs<'_>, ring_axes: Option<[[f64; 3]; 3]>) -> Value {
    let (m, d) = inputs.embedding.dim();
    let mut trace = json!({
        "name": "kernel sets",
        "mode": "markers",
        "customdata": hover_data(inputs),
        "hovertemplate": if inputs.poses.is_some() { HOVER_TEMPLATE } else { HOVER_TEMPLATE_NO_POSE },
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
    if let (Some([first, _, axis]), true) = (ring_axes, d >= 3) {
        // Look down the ring's axis (the static figure's view), its first axis up.
        let eye: Vec<f64> = axis.iter().map(|a| round4(1.9 * a)).collect();
        let up: Vec<f64> = first.iter().map(|&a| round4(a)).collect();
        layout["scene"]["camera"] = json!({
            "eye": {"x": eye[0], "y": eye[1], "z": eye[2]},
            "up": {"x": up[0], "y": up[1], "z": up[2]},
        });
    }
    json!({"data": [trace], "layout": layout})
}

/// `v` rounded to four decimals, to keep the page small (a ten-thousandth of the
/// embedding's or the pose's units is below what the view can show).
fn round4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

/// Coordinate `c` (0 = x, 1 = y, 2 = alpha) of the pose of set `i`, when there are
/// planar poses.
fn set_pose(inputs: &ReportInputs<'_>, i: usize, c: usize) -> Option<f64> {
    inputs.poses.map(|poses| poses[[inputs.kept[i], c]])
}

/// What hovering a point shows, from its `customdata` ([`hover_data`]).
const HOVER_TEMPLATE: &str = "set %{pointNumber}, exploration row %{customdata[0]}<br>x = %{customdata[1]} m, y = %{customdata[2]} m<br>alpha = %{customdata[3]} rad (%{customdata[4]}\u{b0})<br>%{customdata[5]}<extra></extra>";

/// What hovering a point shows when there are no planar poses.
const HOVER_TEMPLATE_NO_POSE: &str =
    "set %{pointNumber}, exploration row %{customdata[0]}<br>%{customdata[1]}<extra></extra>";

/// The data behind the hover text of every set, as short as it can be (plotly builds
/// the text from [`HOVER_TEMPLATE`]): its exploration row, pose (4 significant
/// digits), orientation in degrees and probe label; without planar poses, its row and
/// probe label ([`HOVER_TEMPLATE_NO_POSE`]).
fn hover_data(inputs: &ReportInputs<'_>) -> Vec<Value> {
    let m = inputs.embedding.nrows();
    let pose = |i: usize, c: usize| set_pose(inputs, i, c);
    (0..m)
        .map(|i| {
            let row = inputs.kept[i];
            let label = inputs.probes.row(row);
            let probe = if label[0] >= 0 {
                format!(
                    "probe: orientation {}, cell ({}, {})",
                    label[0], label[1], label[2]
                )
            } else {
                "babbled".to_owned()
            };
            match (pose(i, 0), pose(i, 1), pose(i, 2)) {
                (Some(x), Some(y), Some(alpha)) => json!([
                    row,
                    num(x),
                    num(y),
                    num(alpha),
                    format!("{:.1}", alpha.to_degrees()),
                    probe
                ]),
                _ => json!([row, probe]),
            }
        })
        .collect()
}

/// Sets the trace's type and coordinates for the embedding's dimension (a 3-D scatter
/// of the first three coordinates, a 2-D one, or `q1` against the set index) and
/// returns the matching layout axes.
fn place_points(trace: &mut Value, inputs: &ReportInputs<'_>) -> Value {
    let e = inputs.embedding;
    let (m, d) = e.dim();
    let column = |k: usize| -> Vec<f64> { (0..m).map(|i| round4(e[[i, k]])).collect() };
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
            "margin": {"l": 70, "r": 20, "t": 60, "b": 60},
            "xaxis": {"title": {"text": "q1"}, "automargin": true},
            "yaxis": {"title": {"text": "q2", "standoff": 12}, "scaleanchor": "x", "automargin": true},
        })
    } else {
        // A 1-D embedding against the observer's x (paper Fig. 2, left), or against
        // the set's number when there are no planar poses.
        trace["type"] = json!("scattergl");
        let (x, x_title): (Vec<f64>, &str) = match inputs.poses {
            Some(_) => (
                (0..m)
                    .map(|i| set_pose(inputs, i, 0).map_or(0.0, round4))
                    .collect(),
                "observer's x (m)",
            ),
            None => ((0..m).map(|i| i as f64).collect(), "set"),
        };
        trace["x"] = json!(x);
        trace["y"] = json!(if d == 1 { column(0) } else { vec![0.0; m] });
        json!({
            "margin": {"l": 70, "r": 20, "t": 60, "b": 60},
            "xaxis": {"title": {"text": x_title}, "automargin": true},
            "yaxis": {"title": {"text": "embedding q1", "standoff": 12}, "automargin": true},
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

/// One menu button per pose coordinate that colours the points by it (alpha first,
/// the view's start), and the marker the view starts with.
fn pose_buttons(inputs: &ReportInputs<'_>, marker_size: f64) -> (Vec<Value>, Option<Value>) {
    let m = inputs.embedding.nrows();
    let mut buttons = Vec::new();
    let mut first_marker = None;
    for (c, name, unit) in [(2, "alpha", "rad"), (0, "x", "m"), (1, "y", "m")] {
        let Some(values) = (0..m)
            .map(|i| set_pose(inputs, i, c).map(round4))
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
                "#ddd".to_owned()
            } else {
                let alpha = std::f64::consts::TAU * o as f64 / orientations as f64;
                let c = super::plot::ColorScale::Circular.color(smspace::agent::wrap_angle(alpha));
                format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
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
  var still = document.getElementById("embedding-static");
  var spec = JSON.parse(document.getElementById("embedding-data").textContent);
  function webgl() {
    try {
      var canvas = document.createElement("canvas");
      return !!(window.WebGLRenderingContext &&
        (canvas.getContext("webgl") || canvas.getContext("experimental-webgl")));
    } catch (error) {
      return false;
    }
  }
  if (!webgl()) {
    // Keep the static figure; the interactive view cannot be drawn here.
    body.setAttribute("data-plot-status", "static");
    body.setAttribute("data-webgl", "no");
    body.setAttribute("data-errors", String(window.__reportErrors.length));
    return;
  }
  div.hidden = false;
  if (still) { still.hidden = true; }
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

/// Everything the page shows.
pub(super) struct Page<'p, 'a> {
    pub(super) inputs: &'p ReportInputs<'a>,
    pub(super) tables: &'p [Table],
    pub(super) figures: &'p [(FigureRecord, Rendered)],
    pub(super) warnings: &'p [Warning],
    /// Inline plotly.js and the figures instead of loading them from the run folder.
    pub(super) self_contained: bool,
    /// The ring frame's axes in the embedding's coordinates (3-D embeddings): the
    /// interactive view looks down the third.
    pub(super) ring_axes: Option<[[f64; 3]; 3]>,
}

/// CSS pixels per inch of print a figure is shown at: 1.25 times the CSS inch, so
/// that its 9-point text reads at about the size of the page's text and captions.
const CSS_PX_PER_PRINT_INCH: f64 = 120.0;

/// The figures the static view falls back to, in order of preference: the first
/// drawn shows the embedding from the interactive view's start (along the ring's
/// axis, coloured by alpha).
const FALLBACK_FIGURES: [&str; 3] = [
    "fig5d-embedding-probes",
    "embedding-pose",
    "fig2-learned-manifold",
];

impl Page<'_, '_> {
    /// The whole page.
    pub(super) fn html(&self) -> String {
        let inputs = self.inputs;
        let mut out = String::with_capacity(1 << 20);
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
            "<p>Agent <b>{}</b>: {}</p>\n",
            escape(inputs.agent.name()),
            escape(&overview(inputs))
        ));
        out.push_str("<nav>");
        if !self.warnings.is_empty() {
            out.push_str("<a href=\"#warnings\">warnings</a>");
        }
        out.push_str("<a href=\"#view\">interactive view</a><a href=\"#numbers\">numbers</a><a href=\"#figures\">figures</a><a href=\"#config\">configuration</a></nav>\n");
        self.warnings_html(&mut out);
        out.push_str("<h2 id=\"view\">Interactive view of the embedding</h2>\n");
        out.push_str("<p>Drag to rotate, scroll to zoom; the menu colours the points by a pose coordinate or by probe orientation; hovering a point shows its set, exploration row and pose. The view needs WebGL; where the browser has none, a static figure of the same embedding stands in its place.</p>\n");
        out.push_str("<div id=\"embedding-view\" hidden></div>\n");
        self.fallback_html(&mut out);
        out.push_str("<h2 id=\"numbers\">Numbers</h2>\n");
        for t in self.tables {
            table_html(t, &mut out);
        }
        self.figures_html(&mut out);
        out.push_str("<h2 id=\"config\">Configuration</h2>\n<pre class=\"config\">");
        out.push_str(&escape(inputs.config_toml));
        out.push_str("</pre>\n");
        out.push_str("<script id=\"embedding-data\" type=\"application/json\">");
        out.push_str(&script_json(&plot_spec(inputs, self.ring_axes)));
        if self.self_contained {
            out.push_str("</script>\n<script>\n");
            out.push_str(PLOTLY_JS);
            out.push_str("\n</script>\n");
        } else {
            out.push_str(&format!(
                "</script>\n<script src=\"{PLOTLY_PATH}\"></script>\n"
            ));
        }
        out.push_str(PLOT_SCRIPT);
        out.push_str("\n</body>\n</html>\n");
        out
    }

    /// The "Warnings" section, first after the overview; nothing without warnings.
    fn warnings_html(&self, out: &mut String) {
        if self.warnings.is_empty() {
            return;
        }
        out.push_str("<section class=\"warnings\" id=\"warnings\">\n<h2>Warnings</h2>\n<ul>\n");
        for w in self.warnings {
            out.push_str(&format!(
                "<li><b>{}</b>: {}</li>\n",
                escape(&w.stage),
                escape(&w.message)
            ));
        }
        out.push_str("</ul>\n</section>\n");
    }

    /// The `<img>` of a drawn figure: its file (or its bytes, self-contained) at its
    /// print size ([`CSS_PX_PER_PRINT_INCH`]); `None` when it has no image.
    fn image(&self, record: &FigureRecord, rendered: &Rendered, id: &str) -> Option<String> {
        let alt = escape(&record.caption);
        let width = rendered.print_inches.map_or(String::new(), |(w, _)| {
            format!(" width=\"{}\"", (w * CSS_PX_PER_PRINT_INCH).round())
        });
        let id = if id.is_empty() {
            String::new()
        } else {
            format!(" id=\"{id}\"")
        };
        if self.self_contained {
            if let Some(png) = &rendered.png {
                return Some(format!(
                    "<img{id}{width} alt=\"{alt}\" src=\"data:image/png;base64,{}\">\n",
                    base64::engine::general_purpose::STANDARD.encode(png)
                ));
            }
            return rendered
                .svg
                .as_ref()
                .map(|svg| format!("{}\n", inline_svg(svg)));
        }
        let file = |ext: &str| {
            record
                .files
                .iter()
                .find(|p| p.extension().is_some_and(|e| e == ext))
                .map(|p| p.to_string_lossy().replace('\\', "/"))
        };
        file("png")
            .or_else(|| file("svg"))
            .map(|path| format!("<img{id}{width} alt=\"{alt}\" src=\"{}\">\n", escape(&path)))
    }

    /// The static stand-in of the interactive view, shown until the page finds that
    /// the browser can draw WebGL: the first drawn of [`FALLBACK_FIGURES`], or a
    /// sentence when none was drawn.
    fn fallback_html(&self, out: &mut String) {
        out.push_str("<figure id=\"embedding-static\">\n");
        let chosen = FALLBACK_FIGURES.iter().find_map(|name| {
            self.figures
                .iter()
                .find(|(r, _)| r.name == *name && r.skipped.is_none())
        });
        match chosen.and_then(|(r, rendered)| Some((r, self.image(r, rendered, "embedding-fallback")?))) {
            Some((record, img)) => {
                out.push_str(&img);
                out.push_str(&format!(
                    "<figcaption>A static image of the embedding (the figure {} below), shown because this browser cannot draw the interactive view (no WebGL).</figcaption>\n",
                    escape(&record.name)
                ));
            }
            None => out.push_str(
                "<p id=\"embedding-fallback\">This browser cannot draw the interactive view (no WebGL), and no static figure of the embedding was drawn.</p>\n",
            ),
        }
        out.push_str("</figure>\n");
    }

    /// The figures with their captions, and one sentence on those not drawn.
    fn figures_html(&self, out: &mut String) {
        out.push_str("<h2 id=\"figures\">Figures</h2>\n");
        if let Some(sentence) = skipped_sentence(self.inputs, self.figures.iter().map(|(r, _)| r)) {
            out.push_str(&format!("<p class=\"skipped\">{}</p>\n", escape(&sentence)));
        }
        for (record, rendered) in self.figures {
            if record.skipped.is_some() {
                continue;
            }
            let id = escape(&record.name);
            out.push_str(&format!("<figure id=\"{id}\">\n"));
            if let Some(img) = self.image(record, rendered, "") {
                out.push_str(&img);
            }
            out.push_str(&format!(
                "<figcaption><b>{id}</b>: {}</figcaption>\n</figure>\n",
                escape(&record.caption)
            ));
        }
    }
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
