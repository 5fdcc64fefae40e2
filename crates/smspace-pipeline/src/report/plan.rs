//! Which figures a report draws, with what, and their captions: one method per figure,
//! each deciding from the inputs whether its figure is drawn or skipped (and why).

use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::SeedableRng;

use super::figures::{self, Panel, Recovery};
use super::layout::{self, FigureText};
use super::plot::{self, Print};
use super::view3d::Frame;
use super::{InvarianceData, ReportError, ReportInputs, ReportParams};
use smspace::agent::{MotorSpace, PlanarView};

/// What every figure needs besides the inputs.
pub(super) struct Derived {
    /// `(M, 3 + A)`: the planar pose of every set's exploration row, when there are
    /// poses, then its `A` attribute motors ([`smspace::agent::Agent::attribute_motors`]).
    pub(super) set_poses: Option<Array2<f64>>,
    /// Unit of motor coordinates and of set distances.
    motor_unit: &'static str,
    space: MotorSpace,
    /// The probe sheets, one per orientation (none without planar poses).
    pub(super) surfaces: Vec<figures::ProbeSurface>,
    /// The ring frame of a 3-D embedding ([`figures::ring_frame`]), shared by Fig. 5d,
    /// `embedding-pose` and the interactive view.
    pub(super) ring_frame: Option<Frame>,
}

/// Why the figures of poses are skipped when there are none.
const NO_PLANAR_POSES: &str = "the agent has no planar ground truth (x, y, alpha), nor a 3-D one to see from above, to colour or place the sets by, so the figures of poses are skipped";

/// The poses of the sets, the motor unit and the probe sheets.
pub(super) fn derive(inputs: &ReportInputs<'_>) -> Derived {
    let m = inputs.kept.len();
    // The planar pose, then the attribute motors at each set's start (a pupil's
    // aperture, constant on a kernel set): the embedding is coloured by every column.
    let attributes = inputs.agent.attribute_motors();
    let set_poses = inputs.poses.map(|poses| {
        let mut set_poses = Array2::zeros((m, 3 + attributes.len()));
        for (i, &row) in inputs.kept.iter().enumerate() {
            for c in 0..3 {
                set_poses[[i, c]] = poses[[row, c]];
            }
            for (a, &j) in attributes.iter().enumerate() {
                set_poses[[i, 3 + a]] = inputs.motors[[row, j]];
            }
        }
        set_poses
    });
    let space = inputs.agent.motor_space();
    let motor_unit = if space.is_hinges() {
        "rad"
    } else if space.is_bounded() {
        "m"
    } else {
        "rad or m"
    };
    let surfaces = set_poses
        .as_ref()
        .map(|poses| figures::probe_surfaces(inputs.probes, inputs.kept, poses))
        .unwrap_or_default();
    let ring_frame =
        (inputs.embedding.ncols() >= 3).then(|| figures::ring_frame(inputs.embedding, &surfaces));
    Derived {
        set_poses,
        motor_unit,
        space,
        surfaces,
        ring_frame,
    }
}

/// A seeded sample of `k` of `0..n` (all when `k ≥ n`), sorted; `stream` separates the
/// samples of different figures.
fn sample(n: usize, k: usize, seed: u64, stream: u64) -> Vec<usize> {
    if k >= n {
        return (0..n).collect();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    let mut picked = rand::seq::index::sample(&mut rng, n, k).into_vec();
    picked.sort_unstable();
    picked
}

/// A figure ready to draw, or why it is skipped.
pub(super) enum Planned<'a> {
    Skip(String),
    SensoryManifolds(figures::SensoryManifolds<'a>),
    KernelLines(figures::KernelLines<'a>),
    LearnedManifold(figures::LearnedManifold<'a>),
    Configurations(figures::Configurations),
    KernelSets3d(figures::KernelSets3d<'a>),
    EmbeddingProbes(figures::EmbeddingProbes<'a>),
    EmbeddingPose(figures::EmbeddingPose<'a>),
    Persistence(figures::PersistenceDiagram<'a>),
    DyDx(figures::DyDx<'a>),
    Invariance(figures::Invariance),
    Stress(figures::StressTrace<'a>),
}

/// Calls `$f` on the figure of a planned entry, or gives `$skip`.
macro_rules! with_figure {
    ($planned:expr, $skip:expr, |$fig:ident| $body:expr) => {
        match $planned {
            Planned::Skip(_) => $skip,
            Planned::SensoryManifolds($fig) => $body,
            Planned::KernelLines($fig) => $body,
            Planned::LearnedManifold($fig) => $body,
            Planned::Configurations($fig) => $body,
            Planned::KernelSets3d($fig) => $body,
            Planned::EmbeddingProbes($fig) => $body,
            Planned::EmbeddingPose($fig) => $body,
            Planned::Persistence($fig) => $body,
            Planned::DyDx($fig) => $body,
            Planned::Invariance($fig) => $body,
            Planned::Stress($fig) => $body,
        }
    };
}

impl Planned<'_> {
    /// Draws one image of the figure in memory (nothing when skipped).
    pub(super) fn render(
        &self,
        name: &str,
        format: plot::ImageFormat,
        print: Print,
    ) -> Result<plot::Rendered, ReportError> {
        with_figure!(self, Ok(plot::Rendered::default()), |f| plot::render(
            f, name, format, print
        ))
    }

    /// The figure's text as drawn (`None` when skipped).
    pub(super) fn record(
        &self,
        name: &str,
        print: Print,
    ) -> Result<Option<FigureText>, ReportError> {
        let recorded = with_figure!(self, return Ok(None), |f| layout::record(
            f, name, print.dpi
        ));
        recorded.map(Some).map_err(|reason| ReportError::Draw {
            figure: name.to_owned(),
            reason,
        })
    }
}

/// One entry of the figure plan: `(name, caption, plan)`.
pub(super) type PlannedFigure<'b> = (&'static str, String, Planned<'b>);

/// The figures of the report in order: `(name, caption, plan)`.
pub(super) fn plan<'a: 'b, 'b>(
    inputs: &ReportInputs<'a>,
    params: &ReportParams,
    derived: &'b Derived,
) -> Vec<PlannedFigure<'b>> {
    let print = Print {
        dpi: f64::from(params.dpi),
    };
    let planner = Planner {
        inputs: *inputs,
        derived,
        panel: Panel {
            width: print.inches(params.panel_width_in),
            height: print.inches(params.panel_height_in),
            print,
        },
    };
    let sets_sample = sample(inputs.kept.len(), params.sample_sets, params.seed, 2);
    let loops: Vec<usize> = sets_sample
        .iter()
        .copied()
        .take(figures::MAX_LOOPS)
        .collect();
    let mut figures = vec![
        planner.sensory_manifolds(),
        planner.kernel_lines(&sets_sample),
        planner.learned_manifold(),
        planner.configurations(params),
        planner.kernel_sets_3d(loops),
        planner.embedding_probes(),
        planner.embedding_pose(),
        planner.persistence(),
        planner.dydx(),
        planner.invariance(),
        planner.stress(),
    ];
    if inputs.pose_view == PlanarView::TopView {
        for (name, caption, _) in &mut figures {
            if POSE_FIGURES.contains(name) {
                caption.push_str(TOP_VIEW_NOTE);
            }
        }
    }
    figures
}

/// The figures that place or colour the sets by the planar pose.
const POSE_FIGURES: [&str; 5] = [
    "fig2-kernel-lines",
    "fig2-learned-manifold",
    "fig5a-configurations",
    "fig5d-embedding-probes",
    "embedding-pose",
];

/// What a pose figure of a 3-D agent shows.
const TOP_VIEW_NOTE: &str = " The agent is 3-D: its poses are seen from above, x and y the sensor's position and alpha the heading of its optical axis projected on the xy plane (z and the tilt are not drawn; the agreement analysis uses the full 3-D pose).";

/// What the plan of every figure reads: one method per figure, each deciding
/// whether its figure is drawn and with what.
struct Planner<'a, 'b> {
    inputs: ReportInputs<'a>,
    derived: &'b Derived,
    /// Size of one panel.
    panel: Panel,
}

impl<'a: 'b, 'b> Planner<'a, 'b> {
    /// The observer's `x` for every set.
    fn set_x(&self) -> Option<Vec<f64>> {
        let poses = self.derived.set_poses.as_ref()?;
        Some(poses.column(0).to_vec())
    }

    /// Fig. 1: the sensory manifolds.
    fn sensory_manifolds(&self) -> PlannedFigure<'b> {
        let caption = "Paper Fig. 1 (section 2.2): the sensory manifold traced by the sensor values as the motor sweeps its range, one curve per environment, each starting at the dot: the same motor sweep gives different sensations in different environments.".to_owned();
        let planned = if self.inputs.sensory_manifolds.is_empty() {
            Planned::Skip(
                "no sensory manifolds were given (they are computed for 1-motor agents)".to_owned(),
            )
        } else {
            Planned::SensoryManifolds(figures::SensoryManifolds {
                manifolds: self.inputs.sensory_manifolds,
                motor_unit: self.derived.motor_unit,
                panel: self.panel,
            })
        };
        ("fig1-sensory-manifolds", caption, planned)
    }

    /// Fig. 2, right: the sampled kernel sets in the motor plane.
    fn kernel_lines(&self, sets_sample: &[usize]) -> PlannedFigure<'b> {
        let inputs = &self.inputs;
        let n = inputs.agent.motor_dim();
        let caption = format!(
            "Paper Fig. 2 right (section 2.3): {} kernel sets M^i in the motor plane, each the motor configurations that give the same sensation as its explored configuration m^i (black dot), coloured by the observer's x.",
            sets_sample.len()
        );
        let planned = if n != 2 {
            Planned::Skip(format!(
                "the agent has N = {n} motors; kernel lines in the motor plane are drawn for N = 2"
            ))
        } else if sets_sample.is_empty() {
            Planned::Skip("no kernel sets to draw (no sets traced, or sample_sets = 0)".to_owned())
        } else if let Some(set_x) = self.set_x() {
            Planned::KernelLines(figures::KernelLines {
                sets: inputs.sets.reborrow(),
                starts: sets_sample
                    .iter()
                    .map(|&i| {
                        let row = inputs.motors.row(inputs.kept[i]);
                        (row[0], row[1])
                    })
                    .collect(),
                sample: sets_sample.to_vec(),
                set_x,
                space: self.derived.space.clone(),
                motor_unit: self.derived.motor_unit,
                total: inputs.kept.len(),
                panel: self.panel,
            })
        } else {
            Planned::Skip(NO_PLANAR_POSES.to_owned())
        };
        ("fig2-kernel-lines", caption, planned)
    }

    /// Fig. 2, left: the learned manifold against `x`.
    fn learned_manifold(&self) -> PlannedFigure<'b> {
        let n = self.inputs.agent.motor_dim();
        let m = self.inputs.kept.len();
        let d = self.inputs.embedding.ncols();
        let caption = if d == 1 {
            "Paper Fig. 2 left (section 2.3): the learned 1-D manifold, the embedding coordinate q1 of every set against the observer's x: a monotonic curve means the agent has captured x.".to_owned()
        } else {
            "Paper Fig. 2 (section 2.3): the learned manifold, the first two embedding coordinates of every set, coloured by the observer's x.".to_owned()
        };
        let planned = if m == 0 {
            Planned::Skip("no kernel sets were embedded".to_owned())
        } else if d == 1 || (d >= 2 && n == 2) {
            match self.set_x() {
                Some(set_x) => Planned::LearnedManifold(figures::LearnedManifold {
                    embedding: self.inputs.embedding.reborrow(),
                    set_x,
                    panel: self.panel,
                }),
                None => Planned::Skip(NO_PLANAR_POSES.to_owned()),
            }
        } else {
            Planned::Skip(format!(
                "the embedding has d = {d} and the agent N = {n} motors; see embedding-pose and fig5d-embedding-probes"
            ))
        };
        ("fig2-learned-manifold", caption, planned)
    }

    /// Fig. 5a: a seeded sample of the babbled configurations of the arm.
    fn configurations(&self, params: &ReportParams) -> PlannedFigure<'b> {
        let inputs = &self.inputs;
        let agent = inputs.agent;
        let babbled = smspace::explore::babbled_rows(inputs.probes.view());
        let picked = sample(babbled.len(), params.sample_configurations, params.seed, 1);
        let skeletons: Vec<Vec<[f64; 2]>> = picked
            .iter()
            .map(|&k| agent.skeleton(&inputs.motors.row(babbled[k]).to_vec()))
            .collect();
        let caption = format!(
            "Paper Fig. 5a (section 3.3): {} of the {} explored (babbled) configurations of the {}: each arm from its base (black square), its joints as dots, the sensor's orientation alpha as a red tick at its end; the working space (green) and the lights of environment 1 (gold).",
            picked.len(),
            babbled.len(),
            agent.name()
        );
        let planned = if picked.is_empty() {
            Planned::Skip(
                "no babbled configurations to draw (or sample_configurations = 0)".to_owned(),
            )
        } else if skeletons.iter().all(Vec::is_empty) {
            Planned::Skip(format!(
                "the agent {} has no body to draw (Agent::skeleton is empty)",
                agent.name()
            ))
        } else if let Some(poses) = inputs.poses {
            Planned::Configurations(figures::Configurations {
                alphas: picked.iter().map(|&k| poses[[babbled[k], 2]]).collect(),
                skeletons,
                workspace: inputs.workspace,
                environment: inputs.environments.first().cloned(),
                explored: babbled.len(),
                panel: self.panel,
            })
        } else {
            Planned::Skip(NO_PLANAR_POSES.to_owned())
        };
        ("fig5a-configurations", caption, planned)
    }

    /// Fig. 5b: the sampled kernel sets in 3-D motor space.
    fn kernel_sets_3d(&self, sample: Vec<usize>) -> PlannedFigure<'b> {
        let n = self.inputs.agent.motor_dim();
        let periodic = self.derived.space.is_hinges();
        let caption = format!(
            "Paper Fig. 5b (section 3.3): {} kernel sets M^i in motor space, one colour each, in two 3-D projections (motors m1, m2, m3 and m2, m3, m4).{}",
            sample.len(),
            if periodic {
                " The motors are hinges, so the motor space is a torus: the cube [-pi, pi]^3 with opposite faces identified. A set that reaches a face (open circle) continues from the opposite face (the other open circle of its colour); every set is a closed loop on the torus."
            } else {
                ""
            }
        );
        let planned = if n < 3 {
            Planned::Skip(format!(
                "the agent has N = {n} motors; the 3-D view of kernel sets needs N >= 3"
            ))
        } else if sample.is_empty() {
            Planned::Skip("no kernel sets to draw (no sets traced, or sample_sets = 0)".to_owned())
        } else {
            Planned::KernelSets3d(figures::KernelSets3d {
                sets: self.inputs.sets.reborrow(),
                sample,
                space: self.derived.space.clone(),
                motor_unit: self.derived.motor_unit,
                panel: self.panel,
            })
        };
        ("fig5b-kernel-sets-3d", caption, planned)
    }

    /// Fig. 5d: the embedding with one probe sheet per orientation.
    fn embedding_probes(&self) -> PlannedFigure<'b> {
        let m = self.inputs.kept.len();
        let d = self.inputs.embedding.ncols();
        let surfaces = &self.derived.surfaces;
        let sheets = surfaces.len();
        let cells = surfaces.iter().map(|s| s.cells.len()).max().unwrap_or(0);
        let caption = if d >= 3 {
            format!(
                "Paper Fig. 5d (section 3.3): the CCA embedding of the {m} kernel sets (grey points) with the {sheets} probe sheets, one per sensor orientation alpha (each the grid of up to {cells} sensor positions at that orientation, drawn as a surface), coloured by alpha on a circular colour map. Left (main view), seen along the axis of the ring the sheets form (the normal of the plane through the sheets' centres; u, v span that plane, w is the axis), so that the ring faces the reader; right, the same seen obliquely. The sheets follow one another round the ring in the order of alpha, and the ring closes: the circle of orientations times the plane of positions, the T x R^2 of the paper. The embedding's axes are arbitrary, in the units of the set metric."
            )
        } else {
            format!(
                "Paper Fig. 5d (section 3.3): the 2-D embedding of the {m} kernel sets (grey) with the {sheets} probe sheets, one per sensor orientation alpha, coloured by alpha on a circular colour map."
            )
        };
        let planned = if d < 2 {
            Planned::Skip(format!(
                "the embedding has d = {d}; probe sheets need d >= 2"
            ))
        } else if self.derived.set_poses.is_none() {
            Planned::Skip(NO_PLANAR_POSES.to_owned())
        } else if surfaces.is_empty() {
            Planned::Skip(
                "no probe rows among the kept sets (explore with probes = \"grid\")".to_owned(),
            )
        } else {
            Planned::EmbeddingProbes(figures::EmbeddingProbes {
                embedding: self.inputs.embedding.reborrow(),
                surfaces,
                frame: self.derived.ring_frame,
                panel: self.panel,
            })
        };
        ("fig5d-embedding-probes", caption, planned)
    }

    /// The embedding coloured by each pose coordinate that varies over the sets.
    fn embedding_pose(&self) -> PlannedFigure<'b> {
        let m = self.inputs.kept.len();
        let d = self.inputs.embedding.ncols();
        let Some(set_poses) = &self.derived.set_poses else {
            let caption =
                format!("The embedding of the {m} kernel sets coloured by the observer's pose.");
            return (
                "embedding-pose",
                caption,
                Planned::Skip(NO_PLANAR_POSES.to_owned()),
            );
        };
        let varying: Vec<usize> = (0..set_poses.ncols())
            .filter(|&c| {
                plot::finite_extent(set_poses.column(c).iter().copied())
                    .is_some_and(|(lo, hi)| hi - lo > 1e-9)
            })
            .collect();
        let spearman = |c: usize| {
            let name = smspace::analysis::agreement::POSE_COORDINATES.get(c)?;
            self.inputs
                .analysis
                .and_then(|a| a.agreement.as_ref())
                .and_then(|g| g.coordinates.get(*name).copied().flatten())
        };
        let recovery = if m > 1 && d > 0 {
            figures::recovery(self.inputs.embedding, set_poses, &varying, spearman)
        } else {
            Vec::new()
        };
        let caption = pose_caption(m, &recovery);
        let planned = if m == 0 || d == 0 {
            Planned::Skip("no kernel sets were embedded".to_owned())
        } else if varying.is_empty() {
            Planned::Skip("every pose coordinate is constant over the sets".to_owned())
        } else {
            // Chosen here, once: the PNG, the SVG and the layout check draw the same.
            let views = self.derived.ring_frame.map(|frame| {
                figures::PoseViews::choose(self.inputs.embedding, frame, set_poses, &varying)
            });
            Planned::EmbeddingPose(figures::EmbeddingPose {
                embedding: self.inputs.embedding.reborrow(),
                set_poses,
                coordinates: varying,
                recovery,
                views,
                panel: self.panel,
            })
        };
        ("embedding-pose", caption, planned)
    }

    /// The persistence diagram of the analysis.
    fn persistence(&self) -> PlannedFigure<'b> {
        let caption = "Vietoris-Rips persistence diagram of the set metric rho (the distances between kernel sets): points far above the diagonal are robust features; the Betti numbers read off by the gap rule are in the title (the arm's manifold, a circle of orientations times a disc of positions, gives b = [1, 1]).".to_owned();
        let planned = match self.inputs.analysis {
            None => Planned::Skip("no analysis was run".to_owned()),
            Some(a) if a.persistence.iter().all(Vec::is_empty) => {
                Planned::Skip("the analysis has no persistence bars".to_owned())
            }
            Some(a) => Planned::Persistence(figures::PersistenceDiagram {
                analysis: a,
                distance_unit: self.derived.motor_unit,
                panel: self.panel,
            }),
        };
        ("persistence-diagram", caption, planned)
    }

    /// CCA's `dy–dx` plot.
    fn dydx(&self) -> PlannedFigure<'b> {
        let caption = "CCA's dy-dx plot: the distance of two sets in the embedding (dy) against their learned distance (dx); points on the dashed diagonal are preserved, CCA favours the small distances (lower left).".to_owned();
        let planned = match self.inputs.dydx {
            Some(p) if p.nrows() > 0 => Planned::DyDx(figures::DyDx {
                pairs: p.reborrow(),
                distance_unit: self.derived.motor_unit,
                panel: self.panel,
            }),
            _ => Planned::Skip(
                "no dy-dx sample was given (the embedding method is not CCA, or it was not computed)"
                    .to_owned(),
            ),
        };
        ("dydx", caption, planned)
    }

    /// Set and sensor distances in the first two environments.
    fn invariance(&self) -> PlannedFigure<'b> {
        let caption = "Environment invariance (section 2.3): for the rows traced in two environments, the learned distances between their kernel sets (left) are the same in both environments, while the distances between their raw sensor values (right) are not. Each panel shows pairs up to the 99.5th percentile of its distances.".to_owned();
        let planned = match self.inputs.invariance {
            None => Planned::Skip("no invariance comparison was run".to_owned()),
            Some(inv) if inv.set_distances.len() < 2 => Planned::Skip(
                "the invariance comparison has fewer than two environments".to_owned(),
            ),
            Some(inv) => {
                Planned::Invariance(invariance_figure(inv, self.derived.motor_unit, self.panel))
            }
        };
        ("invariance", caption, planned)
    }

    /// CCA's stress per epoch.
    fn stress(&self) -> PlannedFigure<'b> {
        let report = self.inputs.embed_report;
        let caption =
            "CCA's stress, accumulated over each epoch, as the neighbourhood width lambda shrinks (logarithmic scale)."
                .to_owned();
        let planned = if report.stress_trace.is_empty() {
            Planned::Skip(format!(
                "the embedding method {} records no stress per epoch",
                report.method
            ))
        } else {
            Planned::Stress(figures::StressTrace {
                stress: &report.stress_trace,
                panel: self.panel,
            })
        };
        ("cca-stress", caption, planned)
    }
}

/// The caption of `embedding-pose`: which coordinates the embedding recovers, and how
/// well, in numbers: locally (the neighbours' `R²`) and at all scales (the analysis'
/// Spearman correlation of the learned distance with each coordinate's difference).
fn pose_caption(m: usize, recovery: &[Recovery]) -> String {
    let list = |items: Vec<String>| match items.as_slice() {
        [] => String::new(),
        [one] => one.clone(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    };
    let local = list(
        recovery
            .iter()
            .map(|r| {
                format!(
                    "{} (R\u{b2} = {:.2})",
                    figures::coordinate_name(r.coordinate),
                    r.r2
                )
            })
            .collect(),
    );
    let neighbours = recovery
        .first()
        .map_or(figures::RECOVERY_NEIGHBOURS, |r| r.neighbours);
    let band = |s: f64| {
        if s >= 0.5 {
            "strongly"
        } else if s >= 0.2 {
            "partly"
        } else {
            "weakly"
        }
    };
    let global = list(
        recovery
            .iter()
            .filter_map(|r| {
                r.spearman.map(|s| {
                    format!(
                        "{} {} (Spearman {s:.2})",
                        band(s),
                        figures::coordinate_name(r.coordinate)
                    )
                })
            })
            .collect(),
    );
    let mut text = format!(
        "The embedding of the {m} kernel sets coloured by each varying coordinate of the observer's pose (alpha on a circular colour map; in 3-D each panel is seen, in the ring frame of Fig. 5d, from the view in which its coordinate shows best: the one whose nearest neighbours on screen share the coordinate most)."
    );
    if !local.is_empty() {
        text.push_str(&format!(
            " Locally, a set's {neighbours} nearest sets in the embedding predict its {local}: R\u{b2} is the share of the coordinate's variance they predict (1: neighbours share it, 0: they say nothing of it)."
        ));
    }
    if !global.is_empty() {
        text.push_str(&format!(
            " At all scales, the learned distance between two sets follows {global}: the rank correlation between the distance and the difference in that coordinate (analysis.json, agreement.coordinates); a coordinate with a weak correlation is encoded in the neighbourhoods but hardly in the large distances."
        ));
    }
    text
}

/// The invariance figure of environments 1 and 2 (at least two): an evenly spaced
/// sample of the pairs of common rows, their set distances and sensor distances in
/// each environment, and the Mantel correlations of the pair `(0, 1)` (or the first).
fn invariance_figure(
    inv: &InvarianceData,
    distance_unit: &'static str,
    panel: Panel,
) -> figures::Invariance {
    let pair = inv
        .report
        .pairs
        .iter()
        .find(|p| p.a == 0 && p.b == 1)
        .or(inv.report.pairs.first());
    let c = inv.set_distances[0].nrows();
    let all: Vec<(usize, usize)> = (0..c)
        .flat_map(|i| (i + 1..c).map(move |j| (i, j)))
        .collect();
    let drawn: Vec<(usize, usize)> = plot::stride_sample(all.len(), figures::MAX_SCATTER_POINTS)
        .into_iter()
        .map(|k| all[k])
        .collect();
    let sensor_distance = |s: &Array2<f64>, i: usize, j: usize| {
        s.row(i)
            .iter()
            .zip(s.row(j))
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt()
    };
    let (d0, d1) = (&inv.set_distances[0], &inv.set_distances[1]);
    let (s0, s1) = (&inv.sensors[0], &inv.sensors[1]);
    figures::Invariance {
        set_pairs: drawn
            .iter()
            .map(|&(i, j)| (d0[[i, j]], d1[[i, j]]))
            .collect(),
        sensor_pairs: drawn
            .iter()
            .map(|&(i, j)| (sensor_distance(s0, i, j), sensor_distance(s1, i, j)))
            .collect(),
        mantel: pair.map_or(f64::NAN, |p| p.mantel),
        sensor_mantel: pair.map_or(f64::NAN, |p| p.sensor_mantel),
        environments: (0, 1),
        distance_unit,
        panel,
    }
}
