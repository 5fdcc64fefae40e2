//! The report stage on small real runs: every figure file is a valid PNG/SVG at its
//! print resolution, no two texts of any figure overlap, the HTML loads only files of
//! its run folder (or none, self-contained) and carries the warnings, figures and
//! numbers, the Markdown has the numbers, figures without inputs are skipped with a
//! reason, and bad inputs are errors. When `chromium` is on PATH, the HTML is also
//! opened headless by `.ci/browser-check`.

use std::path::Path;
use std::process::Command;

use ndarray::{Array2, Array3, Axis};
use smspace::agent::{Agent, AgentConfig, Environment};
use smspace::analysis::{analyze, AnalysisParams, AnalysisReport};
use smspace::embed::quality::shepard_pairs;
use smspace::embed::{CcaParams, EmbedReport, Embedding};
use smspace::explore::{explore, Exploration, ExploreParams, Probes};
use smspace::invariance::invariance;
use smspace::kernel::{trace_sets, TraceMethod, TraceParams, TraceSummary};
use smspace::metric::{distance_matrix, DistanceParams, Period};
use smspace::progress::Silent;
use smspace_pipeline::report::{
    figure_texts, write_report, FigureFormats, InvarianceData, ReportError, ReportInputs,
    ReportParams, ReportSummary, SensoryManifold, StageTiming, Warning,
};

/// The outputs of a small run of every stage.
struct Run {
    agent: Box<dyn Agent>,
    environments: Vec<Environment>,
    exploration: Exploration,
    sets: Array3<f64>,
    kept: Vec<usize>,
    trace: TraceSummary,
    embedding: Array2<f64>,
    embed_report: EmbedReport,
    quality: serde_json::Value,
    dydx: Array2<f64>,
    analysis: AnalysisReport,
    invariance: Option<InvarianceData>,
    manifolds: Vec<SensoryManifold>,
    stages: Vec<StageTiming>,
}

fn run(agent: &str, babbled: usize, probes: bool, dim: usize, invariance_rows: usize) -> Run {
    let agent = AgentConfig::preset(agent).unwrap().build().unwrap();
    let environments: Vec<Environment> = (1..=2)
        .map(|seed| {
            Environment::random(
                agent.default_light_count(),
                seed,
                &agent.default_light_region(),
            )
            .unwrap()
        })
        .collect();
    let exploration = explore(
        agent.as_ref(),
        &ExploreParams {
            n: babbled,
            probes: if probes { Probes::Grid } else { Probes::None },
            probe_positions: 3,
            probe_orientations: 4,
            ..ExploreParams::default()
        },
    )
    .unwrap();
    let traced = trace_sets(
        agent.as_ref(),
        Some(&environments[0]),
        exploration.motors.view(),
        exploration.workspace.as_ref(),
        &TraceParams::default().check().unwrap(),
        &Silent,
    )
    .unwrap();
    let period = if agent.motor_space().is_hinges() {
        Period::TwoPi
    } else {
        Period::None
    };
    let metric = DistanceParams::new()
        .metric(smspace::metric::MetricKind::Hausdorff)
        .period(period);
    let distances = distance_matrix(traced.sets.view(), &metric, &Silent).unwrap();
    let embedded = CcaParams::default()
        .dim(dim)
        .epochs(20)
        .seed(1)
        .check()
        .unwrap()
        .fit(&distances, &Silent)
        .unwrap();
    let dydx = shepard_pairs(distances.view(), embedded.coordinates.view(), 5000, 1).unwrap();
    let set_poses = exploration
        .planar_poses()
        .unwrap()
        .select(Axis(0), &traced.kept);
    let analysis = analyze(
        &distances,
        Some(set_poses.view()),
        &AnalysisParams::default().check().unwrap(),
        &Silent,
    )
    .unwrap();
    let invariance = (invariance_rows > 0).then(|| {
        let starts = exploration
            .motors
            .slice_axis(Axis(0), (0..invariance_rows).into());
        let sensory = TraceParams {
            method: TraceMethod::Sensory,
            ..TraceParams::default()
        }
        .check()
        .unwrap();
        let report = invariance(
            agent.as_ref(),
            starts,
            &environments,
            exploration.workspace.as_ref(),
            &sensory,
            smspace::invariance::agent_metric(
                smspace::metric::MetricKind::Hausdorff,
                agent.as_ref(),
            )
            .as_ref(),
            &Silent,
        )
        .unwrap();
        // The figure's data: the common rows' sets traced with the kinematic method
        // (identical in every environment by construction) and their sensor values.
        let c = report.common_sets.min(invariance_rows);
        let rows: Vec<usize> = (0..c).collect();
        let d = distance_matrix(traced.sets.select(Axis(0), &rows).view(), &metric, &Silent)
            .unwrap()
            .into_array();
        let sensors = environments
            .iter()
            .map(|env| {
                let mut s = Array2::zeros((c, agent.sensor_dim()));
                for (k, &r) in rows.iter().enumerate() {
                    let mut out = vec![0.0; agent.sensor_dim()];
                    agent.sense(env, &exploration.motors.row(r).to_vec(), &mut out);
                    s.row_mut(k).assign(&ndarray::ArrayView1::from(&out));
                }
                s
            })
            .collect();
        InvarianceData {
            report,
            set_distances: vec![d.clone(), d],
            sensors,
        }
    });
    let stages = ["explore", "trace", "distances", "embed", "analyze"]
        .iter()
        .enumerate()
        .map(|(k, s)| StageTiming {
            stage: (*s).to_owned(),
            seconds: 0.25 * k as f64,
            cached: k == 0,
        })
        .collect();
    Run {
        agent,
        environments,
        exploration,
        sets: traced.sets,
        kept: traced.kept,
        trace: traced.report.summary,
        embedding: embedded.coordinates,
        embed_report: embedded.report,
        quality: serde_json::json!({"trustworthiness": 0.987654, "continuity": 0.912345, "k": 10}),
        dydx,
        analysis,
        invariance,
        manifolds: Vec::new(),
        stages,
    }
}

fn inputs(run: &Run) -> ReportInputs<'_> {
    ReportInputs {
        name: "test <report> & co",
        description: "A small run for the tests.",
        config_toml: "[agent]\nkind = \"planar-arm\"\n# </script> <b>escaped</b>\n",
        agent: run.agent.as_ref(),
        environments: &run.environments,
        workspace: run.exploration.workspace,
        motors: run.exploration.motors.view(),
        poses: run.exploration.planar_poses(),
        pose_view: smspace::agent::PlanarView::Planar,
        probes: run.exploration.probes.view(),
        sets: run.sets.view(),
        kept: &run.kept,
        trace: &run.trace,
        law: None,
        embedding: run.embedding.view(),
        embed_report: &run.embed_report,
        embed_quality: Some(&run.quality),
        dydx: Some(run.dydx.view()),
        analysis: Some(&run.analysis),
        invariance: run.invariance.as_ref(),
        sensory_manifolds: &run.manifolds,
        stages: &run.stages,
        warnings: &[],
    }
}

/// Checks that every file of every drawn figure is a valid PNG or SVG.
fn check_figure_files(dir: &Path, summary: &ReportSummary) {
    for f in &summary.figures {
        if f.skipped.is_some() {
            assert!(f.files.is_empty(), "{} skipped but has files", f.name);
            continue;
        }
        assert!(!f.files.is_empty(), "{} drawn without files", f.name);
        for file in &f.files {
            let bytes = std::fs::read(dir.join(file)).unwrap();
            match file.extension().and_then(|e| e.to_str()) {
                Some("png") => {
                    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{file:?}");
                    assert_eq!(&bytes[12..16], b"IHDR", "{file:?}");
                    let width = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
                    let height = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
                    assert!(width >= 1000 && height >= 700, "{file:?}: {width}x{height}");
                    assert!(bytes.len() > 5000, "{file:?} is nearly empty");
                    // The physical size: 300 dpi (11811 pixels per metre).
                    let phys = bytes.windows(4).position(|w| w == b"pHYs").expect("pHYs");
                    let ppm = u32::from_be_bytes(bytes[phys + 4..phys + 8].try_into().unwrap());
                    assert_eq!(ppm, 11_811, "{file:?}");
                }
                Some("svg") => {
                    let text = String::from_utf8(bytes).unwrap();
                    assert!(text.contains("<svg width=\"") && text.trim_end().ends_with("</svg>"));
                    assert!(
                        text[..200].contains("in\" height=\""),
                        "{file:?}: no print size"
                    );
                    assert!(text.contains("<text"), "{file:?} has no text");
                }
                other => panic!("unexpected figure file {file:?} ({other:?})"),
            }
        }
    }
}

/// The page without the text inside its `<script>` elements (plotly.js mentions URLs in
/// its strings, which the page never loads).
fn without_script_bodies(html: &str) -> String {
    let mut out = String::new();
    let mut rest = html;
    while let Some(start) = rest.find("<script") {
        let open_end = start + rest[start..].find('>').unwrap() + 1;
        out.push_str(&rest[..open_end]);
        let close = open_end + rest[open_end..].find("</script>").unwrap();
        rest = &rest[close..];
    }
    out.push_str(rest);
    out
}

/// Every file the page loads (`src` and `href` values), sorted, after checking that it
/// names nothing outside its folder.
fn loads(html: &str) -> Vec<String> {
    let markup = without_script_bodies(html);
    let lower = markup.to_lowercase();
    for external in ["http:", "https:", "//", "<link", "url("] {
        let found = lower
            .match_indices("src=\"")
            .chain(lower.match_indices("href=\""))
            .any(|(i, m)| lower[i + m.len()..].starts_with(external));
        assert!(!found, "report.html loads {external}");
        if external == "<link" || external == "url(" {
            assert!(!lower.contains(external), "report.html has {external}");
        }
    }
    let markup = markup.as_str();
    let mut out: Vec<String> = ["src=\"", "href=\""]
        .iter()
        .flat_map(|attr| {
            markup.match_indices(attr).map(move |(i, m)| {
                let rest = &markup[i + m.len()..];
                rest[..rest.find('"').unwrap()].to_owned()
            })
        })
        .filter(|v| !v.starts_with('#') && !v.starts_with("data:"))
        .collect();
    for v in &out {
        assert!(
            !v.contains("..") && !v.starts_with('/'),
            "{v} is outside the folder"
        );
    }
    out.sort();
    out
}

fn figure<'a>(
    summary: &'a ReportSummary,
    name: &str,
) -> &'a smspace_pipeline::report::FigureRecord {
    summary
        .figures
        .iter()
        .find(|f| f.name == name)
        .unwrap_or_else(|| panic!("no figure {name}"))
}

fn chromium() -> bool {
    Command::new("sh")
        .args(["-c", "command -v chromium || command -v chromium-browser"])
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn arm_report_has_every_figure_the_numbers_and_an_interactive_view() {
    let run = run("planar-arm", 40, true, 3, 12);
    let inputs = inputs(&run);
    let dir = tempfile::tempdir().unwrap();
    let summary = write_report(&inputs, &ReportParams::default(), dir.path()).unwrap();
    check_figure_files(dir.path(), &summary);
    for name in [
        "fig5a-configurations",
        "fig5b-kernel-sets-3d",
        "fig5d-embedding-probes",
        "embedding-pose",
        "persistence-diagram",
        "dydx",
        "invariance",
        "cca-stress",
    ] {
        let f = figure(&summary, name);
        assert_eq!(f.skipped, None, "{name}");
        assert_eq!(f.files.len(), 2, "{name}: PNG and SVG");
    }
    for name in [
        "fig1-sensory-manifolds",
        "fig2-kernel-lines",
        "fig2-learned-manifold",
    ] {
        assert!(figure(&summary, name).skipped.is_some(), "{name}");
    }

    // The page loads plotly.js and the figures from its run folder, nothing else.
    let html = std::fs::read_to_string(dir.path().join(&summary.html)).unwrap();
    let drawn: Vec<&str> = summary
        .figures
        .iter()
        .filter(|f| f.skipped.is_none())
        .map(|f| f.name.as_str())
        .collect();
    let loaded = loads(&html);
    let mut expected: Vec<String> = drawn
        .iter()
        .map(|name| format!("figures/{name}.png"))
        .collect();
    expected.push("assets/plotly-2.12.1.min.js".to_owned());
    // The static stand-in of the interactive view: Fig. 5d's image once more.
    expected.push("figures/fig5d-embedding-probes.png".to_owned());
    expected.sort();
    assert_eq!(loaded, expected, "{html}");
    assert_eq!(
        summary.assets,
        vec![Path::new("assets/plotly-2.12.1.min.js")]
    );
    let plotly = std::fs::read_to_string(dir.path().join(&summary.assets[0])).unwrap();
    assert!(plotly.contains("plotly.js v2.12.1"));
    assert!(!html.contains("plotly.js v2.12.1") && !html.contains("data:image"));
    assert!(
        html.len() < 200_000,
        "a linked page is light: {} bytes",
        html.len()
    );
    assert!(html.contains("Plotly.newPlot"));
    assert!(html.contains("<title>test &lt;report&gt; &amp; co</title>"));
    assert!(html.contains("# &lt;/script&gt; &lt;b&gt;escaped&lt;/b&gt;"));
    assert!(
        html.contains("4 motors, 6 sensors; 2 environments;"),
        "grammar"
    );
    let betti = format!(
        "[{}]",
        run.analysis
            .betti
            .iter()
            .map(|b| b.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    assert!(html.contains(&betti), "betti {betti} missing");
    assert!(html.contains("0.9877"), "trustworthiness missing");
    // The three toy figures, said once in one sentence.
    assert_eq!(html.matches("do not apply to this run").count(), 1);
    assert!(html.contains(
        "The figures fig1-sensory-manifolds, fig2-kernel-lines and fig2-learned-manifold do not apply"
    ));
    assert!(!html.contains("skipped:"));

    // Self-contained: the same page with plotly.js and the figures inside, loading nothing.
    let whole = tempfile::tempdir().unwrap();
    let params = ReportParams {
        self_contained: true,
        ..ReportParams::default()
    };
    let summary_whole = write_report(&inputs, &params, whole.path()).unwrap();
    assert!(summary_whole.assets.is_empty());
    assert!(!whole.path().join("assets").exists());
    let page = std::fs::read_to_string(whole.path().join("report.html")).unwrap();
    assert!(loads(&page).is_empty(), "{:?}", loads(&page));
    assert_eq!(
        without_script_bodies(&page)
            .matches("data:image/png;base64,")
            .count(),
        drawn.len() + 1,
        "every figure, and Fig. 5d once more as the static view"
    );
    assert!(page.contains("plotly.js v2.12.1") && page.len() > 3_000_000);

    let md = std::fs::read_to_string(dir.path().join(&summary.markdown)).unwrap();
    assert!(md.contains("](figures/fig5d-embedding-probes.png)"));
    assert!(md.contains("| Betti numbers"));
    assert!(md.contains(&betti));
    assert!(md.contains("Stage times") && md.contains("| total"));
    assert!(md.contains("Mantel r (sets)"));

    // The same inputs give the same files.
    let again = tempfile::tempdir().unwrap();
    let summary2 = write_report(&inputs, &ReportParams::default(), again.path()).unwrap();
    assert_eq!(summary, summary2);
    for f in summary.figures.iter().flat_map(|f| &f.files) {
        let a = std::fs::read(dir.path().join(f)).unwrap();
        let b = std::fs::read(again.path().join(f)).unwrap();
        assert!(a == b, "{f:?} differs between two runs");
    }

    if chromium() {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.ci/browser-check");
        let out = Command::new("bash")
            .arg(script)
            .arg(dir.path().join(&summary.html))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "browser check failed:\n{}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    } else {
        // CI installs chromium and sets this, so that a missing browser fails there
        // instead of skipping.
        assert!(
            std::env::var_os("SMSPACE_REQUIRE_BROWSER").is_none(),
            "SMSPACE_REQUIRE_BROWSER is set but chromium is not on PATH"
        );
        eprintln!("chromium is not on PATH: skipped the browser check of report.html");
    }
}

#[test]
fn figures_without_their_inputs_are_skipped_with_a_reason() {
    let run = run("planar-arm", 30, false, 2, 0);
    let full = inputs(&run);
    let mut inputs = full;
    inputs.analysis = None;
    inputs.dydx = None;
    let dir = tempfile::tempdir().unwrap();
    // An earlier report in both formats, with figures that are now skipped.
    let both = ReportParams {
        formats: FigureFormats::PngAndSvg,
        ..ReportParams::default()
    };
    write_report(&full, &both, dir.path()).unwrap();
    let figures = dir.path().join("figures");
    assert!(figures.join("embedding-pose.svg").is_file());
    assert!(figures.join("persistence-diagram.png").is_file());
    let params = ReportParams {
        formats: FigureFormats::Png,
        ..ReportParams::default()
    };
    let summary = write_report(&inputs, &params, dir.path()).unwrap();
    check_figure_files(dir.path(), &summary);
    // Only what this report shows stays: no SVG, no figure of a skipped plot.
    assert!(!figures.join("embedding-pose.svg").exists());
    assert!(!figures.join("persistence-diagram.png").exists());
    assert!(figures.join("embedding-pose.png").is_file());
    let reason = |name: &str| figure(&summary, name).skipped.clone().unwrap_or_default();
    assert!(reason("fig5d-embedding-probes").contains("no probe rows"));
    assert!(reason("persistence-diagram").contains("no analysis"));
    assert!(reason("dydx").contains("no dy-dx"));
    assert!(reason("invariance").contains("no invariance"));
    let pose = figure(&summary, "embedding-pose");
    assert_eq!(pose.files.len(), 1, "PNG only");
    let md = std::fs::read_to_string(dir.path().join(&summary.markdown)).unwrap();
    assert!(md.contains("fig5d-embedding-probes"));
    assert!(
        !md.contains("no probe rows"),
        "reasons are in report.json, not the page"
    );
}

#[test]
fn toy_report_draws_the_sensory_manifolds_and_the_kernel_lines() {
    let mut run = run("toy-redundant", 30, false, 1, 0);
    let t = 50;
    let motors = Array2::from_shape_fn((t, 2), |(i, _)| -1.0 + 2.0 * i as f64 / (t - 1) as f64);
    run.manifolds = run
        .environments
        .iter()
        .enumerate()
        .map(|(k, env)| {
            let mut sensors = Array2::zeros((t, 2));
            for i in 0..t {
                let mut out = [0.0; 2];
                run.agent.sense(env, &motors.row(i).to_vec(), &mut out);
                sensors[[i, 0]] = out[0];
                sensors[[i, 1]] = out[1];
            }
            SensoryManifold {
                label: format!("environment {}", k + 1),
                motors: motors.clone(),
                sensors,
            }
        })
        .collect();
    let inputs = inputs(&run);
    let dir = tempfile::tempdir().unwrap();
    let params = ReportParams {
        formats: FigureFormats::Svg,
        ..ReportParams::default()
    };
    let summary = write_report(&inputs, &params, dir.path()).unwrap();
    check_figure_files(dir.path(), &summary);
    for name in [
        "fig1-sensory-manifolds",
        "fig2-kernel-lines",
        "fig2-learned-manifold",
    ] {
        assert_eq!(figure(&summary, name).skipped, None, "{name}");
    }
    assert!(figure(&summary, "fig5a-configurations")
        .skipped
        .as_deref()
        .is_some_and(|r| r.contains("no body")));
    let html = std::fs::read_to_string(dir.path().join(&summary.html)).unwrap();
    assert!(
        html.contains("src=\"figures/fig1-sensory-manifolds.svg\""),
        "SVG figures are linked"
    );
    assert!(html.contains("1 motor") || html.contains("2 motors"));
    assert!(html.contains("\"scattergl\""));
}

#[test]
fn inputs_that_do_not_fit_are_errors() {
    let run = run("planar-arm", 30, false, 3, 0);
    let dir = tempfile::tempdir().unwrap();
    let mut inputs = inputs(&run);
    let short = &run.kept[..run.kept.len() - 1];
    inputs.kept = short;
    let err = write_report(&inputs, &ReportParams::default(), dir.path()).unwrap_err();
    assert!(
        matches!(err, ReportError::Input { what: "kept", .. }),
        "{err}"
    );
    let inputs = self::inputs(&run);
    let params = ReportParams {
        panel_width_in: 0.5,
        ..ReportParams::default()
    };
    let err = write_report(&inputs, &params, dir.path()).unwrap_err();
    assert!(err.to_string().contains("panel_width_in = 0.5"), "{err}");
    let params = ReportParams {
        dpi: 5000,
        ..ReportParams::default()
    };
    let err = write_report(&inputs, &params, dir.path()).unwrap_err();
    assert!(err.to_string().contains("dpi = 5000"), "{err}");
}

/// Every drawn figure of `run` has texts that neither overlap nor leave the figure,
/// all at least 9 pt at the print size.
fn assert_clean_text(run: &Run, what: &str) {
    let inputs = inputs(run);
    let texts = figure_texts(&inputs, &ReportParams::default()).unwrap();
    assert!(!texts.is_empty(), "{what}: no figure drawn");
    let mut problems = Vec::new();
    for figure in &texts {
        assert!(
            figure.boxes.len() >= 3,
            "{what}: {} has only {} texts",
            figure.name,
            figure.boxes.len()
        );
        problems.extend(figure.problems());
    }
    assert!(problems.is_empty(), "{what}:\n{}", problems.join("\n"));
}

#[test]
fn no_two_texts_of_any_figure_overlap() {
    // The arm with the probe grid and the invariance comparison: every arm figure.
    assert_clean_text(&run("planar-arm", 40, true, 3, 12), "arm, d = 3");
    // The arm embedded in 2-D: the planar versions of Fig. 5d and embedding-pose.
    assert_clean_text(&run("planar-arm", 30, true, 2, 0), "arm, d = 2");
    // The toys: Fig. 1, Fig. 2 and the 1-D embedding.
    let mut redundant = run("toy-redundant", 30, false, 1, 12);
    redundant.manifolds = sweep(&redundant, 50);
    assert_clean_text(&redundant, "toy-redundant");
    let mut line = run("toy-line", 40, false, 1, 12);
    line.manifolds = sweep(&line, 50);
    assert_clean_text(&line, "toy-line");
}

/// The check finds overlaps: two texts drawn on top of each other are reported.
#[test]
fn overlapping_texts_are_found() {
    // 9 pt at 300 dpi is an em of 37.5 pixels.
    let text = |name: &str, left: i32, em_px: f64| smspace_pipeline::report::TextBox {
        text: name.to_owned(),
        left,
        top: 10,
        right: left + 40,
        bottom: 30,
        em_px,
    };
    let figure = smspace_pipeline::report::FigureText {
        name: "f".to_owned(),
        size: (300, 100),
        dpi: 300.0,
        boxes: vec![
            text("a", 10, 40.0),
            text("b", 45, 40.0),
            text("c", 270, 40.0),
            text("d", 150, 30.0),
        ],
    };
    let problems = figure.problems();
    assert_eq!(problems.len(), 3, "{problems:?}");
    assert!(problems
        .iter()
        .any(|p| p.contains("'a'") && p.contains("'b'") && p.contains("overlap")));
    assert!(problems
        .iter()
        .any(|p| p.contains("'c'") && p.contains("leaves")));
    assert!(problems
        .iter()
        .any(|p| p.contains("'d' is 7.2 pt, less than 9 pt")));
}

/// The raw sensory manifold of each environment along a sweep of the motors from -1 to 1.
fn sweep(run: &Run, t: usize) -> Vec<SensoryManifold> {
    let n = run.agent.motor_dim();
    let k = run.agent.sensor_dim();
    let motors = Array2::from_shape_fn((t, n), |(i, _)| -1.0 + 2.0 * i as f64 / (t - 1) as f64);
    run.environments
        .iter()
        .enumerate()
        .map(|(e, env)| {
            let mut sensors = Array2::zeros((t, k));
            for i in 0..t {
                let mut out = vec![0.0; k];
                run.agent.sense(env, &motors.row(i).to_vec(), &mut out);
                sensors.row_mut(i).assign(&ndarray::ArrayView1::from(&out));
            }
            SensoryManifold {
                label: format!("environment {}", e + 1),
                motors: motors.clone(),
                sensors,
            }
        })
        .collect()
}

#[test]
fn warnings_open_the_report() {
    let mut run = run("toy-line", 40, false, 1, 0);
    // An unreliable dimension estimate, as the analysis writes it for lattice data.
    let twonn = &mut run.analysis.intrinsic_dimension.twonn_detail.reliability;
    twonn.status = smspace::analysis::dimension::ReliabilityStatus::Unreliable;
    twonn.reasons = vec![
        "TwoNN: 80.0 % of the points have their two nearest neighbours equally far".to_owned(),
    ];
    let extra = [Warning::new("trace", "a warning passed on by the pipeline")];
    // A law learned from too small a log warns in its report (`law` of sets.trace.json).
    let law = serde_json::json!({
        "method": "invariants",
        "warnings": ["9000 fitted samples are 21 per dimension of a sensory manifold of dimension 3"],
    });
    let mut inputs = inputs(&run);
    inputs.warnings = &extra;
    inputs.law = Some(&law);
    inputs.environments = &run.environments[..1];
    let dir = tempfile::tempdir().unwrap();
    let summary = write_report(&inputs, &ReportParams::default(), dir.path()).unwrap();
    assert_eq!(
        summary.warnings[0],
        Warning::new(
            "learn",
            "9000 fitted samples are 21 per dimension of a sensory manifold of dimension 3"
        ),
        "the law's warnings come first"
    );
    let messages: Vec<&str> = summary
        .warnings
        .iter()
        .map(|w| w.message.as_str())
        .collect();
    // toy-line's sets are single points (no redundancy), the estimate above, and the
    // pipeline's warning.
    assert!(
        messages.iter().any(|m| m.contains("is a single point")),
        "{messages:?}"
    );
    assert!(messages
        .iter()
        .any(|m| m.contains("TwoNN intrinsic dimension") && m.contains("80.0 %")));
    assert!(messages.contains(&"a warning passed on by the pipeline"));
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    let warnings = html.find("<h2>Warnings</h2>").expect("a Warnings section");
    assert!(
        warnings < html.find("id=\"view\"").unwrap(),
        "warnings come first"
    );
    assert!(
        html.contains("1 motor, 2 sensors; 1 environment;"),
        "grammar"
    );
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(md.find("## Warnings").unwrap() < md.find("## Numbers").unwrap());
    assert!(
        md.lines()
            .any(|l| l.contains("| TwoNN reliability") && l.contains("| unreliable: 80.0 %")),
        "{md}"
    );

    // A run with nothing to flag (every set a closed loop, estimates reliable, one
    // environment) has no Warnings section.
    let mut clean = self::run("planar-arm", 30, false, 3, 0);
    assert_eq!(clean.trace.by_status.keys().collect::<Vec<_>>(), ["closed"]);
    // 30 sets are too few for the gap rule to read H0 clearly (a bar at 40 % of the
    // threshold): that flag is cleared here, as the dimension's below.
    clean.analysis.betti_ambiguities.clear();
    let d = &mut clean.analysis.intrinsic_dimension;
    for r in [
        &mut d.twonn_detail.reliability,
        &mut d.mle_detail.reliability,
    ] {
        r.status = smspace::analysis::dimension::ReliabilityStatus::Reliable;
        r.reasons.clear();
    }
    let mut inputs = self::inputs(&clean);
    inputs.environments = &clean.environments[..1];
    let dir = tempfile::tempdir().unwrap();
    let summary = write_report(&inputs, &ReportParams::default(), dir.path()).unwrap();
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(!html.contains("Warnings") && !html.contains("#warnings"));
}

/// The value of the row `key` of a Markdown table of `md`: `| key | value |`.
fn md_row<'a>(md: &'a str, key: &str) -> &'a str {
    md.lines()
        .find_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            if cells.len() == 4 && cells[1] == key {
                Some(cells[2])
            } else {
                None
            }
        })
        .unwrap_or_else(|| panic!("no row {key} in\n{md}"))
}

#[test]
fn the_persistence_diagram_draws_infinite_bars_at_the_tables_threshold() {
    let run = run("planar-arm", 40, true, 3, 0);
    let inputs = inputs(&run);
    let dir = tempfile::tempdir().unwrap();
    let summary = write_report(&inputs, &ReportParams::default(), dir.path()).unwrap();
    let md = std::fs::read_to_string(dir.path().join(&summary.markdown)).unwrap();
    // The table: "3.276 (enclosing-radius)".
    let threshold = md_row(&md, "Rips threshold").split(' ').next().unwrap();
    let value: f64 = threshold.parse().unwrap();
    assert!(
        (value - run.analysis.homology.threshold).abs() <= 1e-3 * value.abs(),
        "{threshold} vs {}",
        run.analysis.homology.threshold
    );
    // The figure names the same number where it draws the infinite bars.
    let texts = figure_texts(&inputs, &ReportParams::default()).unwrap();
    let persistence = texts
        .iter()
        .find(|f| f.name == "persistence-diagram")
        .unwrap();
    // The legend may wrap its entry over two lines: read the texts in order.
    let all = persistence
        .boxes
        .iter()
        .map(|t| t.text.as_str())
        .collect::<Vec<_>>()
        .join(" ");
    let wanted = format!("drawn at the Rips threshold {threshold}");
    assert!(all.contains(&wanted), "{wanted} not in {all}");
}

#[test]
fn the_page_has_a_static_view_without_webgl_named_metrics_and_wrapped_configuration() {
    let run = run("planar-arm", 40, true, 3, 0);
    let inputs = inputs(&run);
    let dir = tempfile::tempdir().unwrap();
    let summary = write_report(&inputs, &ReportParams::default(), dir.path()).unwrap();
    let html = std::fs::read_to_string(dir.path().join(&summary.html)).unwrap();
    // The static figure is shown by default; the interactive view is hidden until a
    // WebGL context can be created.
    assert!(
        html.contains("<div id=\"embedding-view\" hidden></div>"),
        "{html}"
    );
    let fallback = html
        .find("id=\"embedding-fallback\"")
        .expect("a static image of the embedding");
    let tag_start = html[..fallback].rfind('<').unwrap();
    let tag = &html[tag_start..tag_start + html[tag_start..].find('>').unwrap()];
    assert!(
        tag.starts_with("<img") && tag.contains("src=\"figures/fig5d-embedding-probes.png\""),
        "{tag}"
    );
    assert!(
        html.contains("getContext(\"webgl\")") && html.contains("data-plot-status\", \"static\"")
    );
    // The interactive view starts coloured by alpha, looking down the ring's axis.
    assert!(
        html.contains("\"camera\":{\"eye\":"),
        "no camera along the ring's axis"
    );
    // Figures at their print size: a 7-inch figure is 840 CSS pixels wide.
    assert!(
        html.contains("<img width=\"840\" alt=\"Paper Fig. 5d"),
        "figure widths"
    );
    // The configuration block wraps its long lines inside its box.
    assert!(html.contains("<pre class=\"config\">"));
    let pre_style = html
        .lines()
        .find(|l| l.starts_with("pre {"))
        .expect("a style for pre");
    assert!(
        pre_style.contains("white-space: pre-wrap")
            && pre_style.contains("overflow-wrap: anywhere"),
        "{pre_style}"
    );
    // The two trustworthiness values are named apart and explained where they stand.
    for needle in [
        "trustworthiness of the embedding vs the learned distances (k = ",
        "trustworthiness of the learned distances vs the poses (k = ",
        "compare the embedding with the learned distances between the sets",
        "compare the learned distances with the distances between the observer&#39;s poses",
    ] {
        assert!(html.contains(needle), "{needle} missing");
    }
    assert!(
        !html.contains("<td>trustworthiness</td>"),
        "an unnamed trustworthiness"
    );
}
