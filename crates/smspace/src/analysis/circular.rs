//! A circular coordinate for every set from the manifold's loop: persistent cohomology
//! turned into a map to the circle (de Silva, Morozov & Vejdemo-Johansson, "Persistent
//! cohomology and circular coordinates", Discrete Comput. Geom. 45, 2011; the sparse,
//! landmark-based form of Perea, "Sparse circular coordinates via principal
//! Z-bundles", 2020, as in the DREiMac library).
//!
//! The paper reads "circle × plane" off a figure. Betti numbers say that the manifold
//! has one loop; this module says *which* number on the circle every set holds, so
//! that the loop can be scored against the orientation it should be.
//!
//! 1. **Landmarks.** `L` max–min landmarks `ℓ_1 … ℓ_L` of the distance matrix `D`,
//!    with covering radius `ε = max_x min_k D(x, ℓ_k)`. The Rips persistence of the
//!    landmarks gives the longest `H1` bar `[b, d)` (`d` the Rips threshold when the
//!    bar is infinite).
//! 2. **Scale.** Balls of radius `r` around the landmarks, with
//!    `r = (1 − f) · max(ε, b/2) + f · d/2` (`f` = [`CircleParams::scale`], default ½):
//!    every set lies in a ball (`r > ε`), and the Rips complex `K` of the landmarks at
//!    `t = 2r` (edges `D(ℓ_i, ℓ_k) ≤ t`, triangles whose three edges are) still holds
//!    the loop (`b ≤ t < d`). Without such an `r` (`max(ε, b/2) ≥ d/2`) the loop is
//!    shorter than the landmarks resolve: an error says to take more of them.
//! 3. **Integer cocycle.** A 1-cochain `z` on the edges (`z_ki = −z_ik`) is a
//!    cocycle when `(δz)_ijk = z_ij + z_jk − z_ik = 0` on every triangle. Every class of
//!    `H¹(K)` has one representative that vanishes on a spanning tree of `K`; the
//!    other edges follow from the triangles, each triangle with one edge unknown fixing
//!    it, and a new free parameter taken when none does. Triangles whose three edges are
//!    known give linear constraints on the parameters; their null space, over `Z/p`
//!    (`p = 2³¹ − 1`), is `H¹(K; Z/p)`. A class is lifted to the integers by scaling it
//!    so that one edge holds 1 and taking symmetric residues; the lift is kept when it is
//!    a cocycle over `Z` (checked on every triangle).
//! 4. **Harmonic smoothing.** `f` minimises `Σ_{edges} w_ik (z_ik − (f_k − f_i))²`
//!    with `w_ik = 1 / (deg_i deg_k)` (the weighted graph Laplacian `Δ_w f = δᵀ W z`).
//!    The weights take the sampling density out: with unit weights the number of edges
//!    in a region grows like the density squared, and the coordinate would turn slowly
//!    where the sets are dense (on 120 random points of a circle, circular correlation
//!    0.93 with the angle; with these weights 0.99). `h = z − δf` is the harmonic
//!    representative,
//!    and the landmarks' coordinate is `θ_i = −f_i mod 1`, so that along an edge
//!    `θ_k − θ_i ≡ h_ik`. With more than one class in `K`, the class of least
//!    harmonic energy `Σ h²` is taken (the widest loop) and the count is reported.
//! 5. **Every set.** With the bump `φ_k(x) ∝ (r − D(x, ℓ_k))₊²`, normalised to sum 1,
//!    and `j` the landmark of largest weight,
//!    `θ(x) = θ_j + Σ_k φ_k(x) h_jk  (mod 1)`, reported in radians `2π θ ∈ [0, 2π)`.
//!
//! **Score.** Against every angular coordinate `α` of the observer's pose, the
//! circular correlation of Fisher & Lee (Biometrika 70, 1983),
//! `ρ = Σ_{i<j} sin(α_i − α_j) sin(β_i − β_j) / √(Σ_{i<j} sin²(α_i − α_j) Σ_{i<j} sin²(β_i − β_j))`
//! with `β = 2πθ`, which needs no mean direction (the orientations are spread over the
//! whole circle, where a mean direction is not defined); `|ρ|` is reported, with the
//! sign as `reversed`: the learned circle has no preferred direction. Beside it, the
//! mean resultant length of
//! `α ∓ β`, `R = max_± |mean e^{i(α ∓ β)}|`, which is 1 when the two agree up to a
//! rotation (and reflection) of the circle.
//!
//! **The plane.** With the circle a number, the rest of "circle × plane" is scored in
//! slices of it: the sets whose coordinate lies in one of 12 arcs of `2π/12` are laid
//! out in two dimensions by classical scaling of their distances (`B = −½ J D² J`, its
//! two leading eigenvectors scaled by `√λ`), and the observer's positions (the first
//! two linear coordinates of the pose) are fitted affinely from them; the median `R²`
//! over the slices says how much of the position the plane's two coordinates carry.
//!
//! **Which orientation.** The class of the loop is fixed by the manifold, but a circular
//! coordinate is not: `θ + g` is one too, for any function `g` of the plane. The
//! harmonic one is the smoothest *in the learned metric*, and the learned metric is a
//! distance between sets of motor configurations: for an arm, turning the first joint
//! by `δ` moves every configuration of a set by `δ` along one motor, so the pose turned
//! about the base, `(R_δ (x, y), α + δ)`, is at distance at most `δ`. Orientation is
//! then measured from the bearing of the sensor seen from the base, not from the
//! world's axis. For a planar pose the agreement is therefore also reported against
//! `α − atan2(y, x)` (the key [`BEARING_RELATIVE`]; the pose frame's origin is the
//! base of the built-in chains). On the paper's arm (3 500 sets, `curve` metric) the
//! coordinate reads `|ρ| = 0.884` against `α` and `0.997` against `α − atan2(y, x)`
//! (`smspace analyze --distances D.npy --poses poses.npy` on the run folder of
//! `smspace run experiments/paper-arm.toml --set scale.path=dense`).

use std::collections::BTreeMap;

use ndarray::{ArrayView2, Axis};
use serde::{Deserialize, Serialize};

use super::{rips_persistence, AnalysisError};
use crate::agent::{CoordinateKind, GroundTruthView};
use crate::neighbours::{farthest_first, DenseDistances};
use crate::params::InvalidParameter;
use crate::progress::Silent;

/// The key of the planar orientation measured from the bearing of the sensor seen
/// from the origin (module docs).
pub const BEARING_RELATIVE: &str = "alpha - atan2(y, x)";

/// The prime of the coefficients.
const PRIME: u64 = 2_147_483_647;
/// The most free parameters the triangle propagation may take before it gives up.
const MAX_PARAMETERS: usize = 256;
/// The largest integer a lifted cocycle may hold.
const MAX_LIFT: i64 = 64;
/// The most landmarks (the complex's edge table is `L × L`).
pub const MAX_LANDMARKS: usize = 2000;

/// Parameters of the circular coordinate (`[analysis]` `circle_landmarks`,
/// `circle_scale`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CircleParams {
    /// Max–min landmarks `L` (at most [`MAX_LANDMARKS`], at least 3).
    pub landmarks: usize,
    /// `f ∈ (0, 1)`: where the balls' radius lies between the loop's birth (or the
    /// covering radius) and its death, as halves of Rips scales.
    pub scale: f64,
}

impl CircleParams {
    /// Checks `landmarks ∈ [3, MAX_LANDMARKS]` and `scale ∈ (0, 1)`.
    pub fn check(&self) -> Result<(), InvalidParameter> {
        if !(3..=MAX_LANDMARKS).contains(&self.landmarks) {
            return Err(InvalidParameter::new(
                "analysis",
                "circle_landmarks",
                self.landmarks,
                format!("must be 0 (no circular coordinate) or in [3, {MAX_LANDMARKS}]"),
            ));
        }
        if !(self.scale.is_finite() && self.scale > 0.0 && self.scale < 1.0) {
            return Err(InvalidParameter::new(
                "analysis",
                "circle_scale",
                self.scale,
                "must be in (0, 1)",
            ));
        }
        Ok(())
    }
}

/// How a circular coordinate agrees with one angular coordinate of the pose.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CircleAgreement {
    /// `|ρ|`, the circular correlation (module docs).
    pub circular_correlation: f64,
    /// Whether `ρ < 0`: the learned circle runs the other way.
    pub reversed: bool,
    /// The mean resultant length `R` of the difference (module docs).
    pub resultant: f64,
}

/// How well the sets at (nearly) one circle coordinate lay out their positions: the
/// plane's two coordinates, scored (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlaneAgreement {
    /// Slices of the circle scored (of [`PLANE_SLICES`]; a slice needs
    /// [`PLANE_MIN_SETS`] sets).
    pub slices: usize,
    /// The median number of sets in a scored slice.
    pub sets_per_slice: usize,
    /// The median over the slices of `R²`, the positions fitted affinely from the
    /// slice's two classical-scaling coordinates.
    pub r_squared: f64,
    /// The least `R²` of a slice.
    pub r_squared_min: f64,
}

/// Slices of the circle the plane is scored in.
pub const PLANE_SLICES: usize = 12;
/// The fewest sets a slice is scored with.
pub const PLANE_MIN_SETS: usize = 10;

/// The circular coordinate of every set and how it was found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CircleCoordinate {
    /// Landmarks used.
    pub landmarks: usize,
    /// Their covering radius `ε`.
    pub covering_radius: f64,
    /// The longest `H1` bar of the landmarks, `[birth, death]` (death: the threshold
    /// when infinite).
    pub bar: [f64; 2],
    /// The balls' radius `r`.
    pub radius: f64,
    /// The Rips scale `t = 2r` of the complex.
    pub scale: f64,
    /// Edges of the complex.
    pub edges: usize,
    /// Triangles of the complex.
    pub triangles: usize,
    /// `dim H¹(K; Z/p)`: 1 for one loop.
    pub classes: usize,
    /// The largest `|z|` of the integer cocycle.
    pub largest_integer: i64,
    /// Per angular coordinate of the pose (by name), the agreement; empty without a
    /// ground truth or an angle.
    pub agreement: BTreeMap<String, CircleAgreement>,
    /// The plane at fixed circle coordinate, scored against the positions (module
    /// docs); `None` without a ground truth of two linear coordinates or too few sets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane: Option<PlaneAgreement>,
    /// The coordinate of every set, radians in `[0, 2π)` (written as its own array,
    /// not in the report).
    #[serde(skip)]
    pub values: Vec<f64>,
}

/// The circular coordinate of the points of `distances` (`M × M`), scored against the
/// angular coordinates of `truth` when given (module docs). `Ok(None)`: the landmarks
/// have no loop.
pub fn circle_coordinate(
    distances: ArrayView2<'_, f64>,
    truth: Option<GroundTruthView<'_>>,
    params: &CircleParams,
) -> Result<Option<CircleCoordinate>, AnalysisError> {
    params.check()?;
    let n = distances.nrows();
    let landmarks = farthest_first(&DenseDistances::new(distances)?, params.landmarks, 0)?;
    let rows = &landmarks.rows;
    let l = rows.len();
    let sub = distances.select(Axis(0), rows).select(Axis(1), rows);
    let persistence = rips_persistence(sub.view(), 1, None, &Silent)?;
    let threshold = persistence.threshold;
    let Some(bar) = persistence
        .diagrams
        .get(1)
        .and_then(|bars| {
            bars.iter()
                .max_by(|a, b| a.length(threshold).total_cmp(&b.length(threshold)))
        })
        .copied()
    else {
        return Ok(None);
    };
    let (birth, death) = (bar.birth, bar.death.unwrap_or(threshold));
    let epsilon = landmarks.covering_radius;
    let low = epsilon.max(birth / 2.0);
    if low >= death / 2.0 {
        return Err(AnalysisError::Degenerate {
            what: "the circular coordinate",
            reason: format!(
                "the longest loop of {l} landmarks lives on [{birth:.4}, {death:.4}), shorter than their covering radius {epsilon:.4} resolves (it must die after twice the radius); take more landmarks (circle_landmarks)"
            ),
        });
    }
    let radius = (1.0 - params.scale) * low + params.scale * death / 2.0;
    let scale = 2.0 * radius;
    let complex = Complex::at(sub.view(), scale);
    let cocycle = integer_cocycle(&complex)?;
    let (theta, harmonic) = (&cocycle.theta, &cocycle.harmonic);
    let values: Vec<f64> = (0..n)
        .map(|x| {
            let row = distances.row(x);
            let near: Vec<(usize, f64)> = rows
                .iter()
                .enumerate()
                .filter_map(|(k, &lk)| {
                    let gap = radius - row[lk];
                    (gap > 0.0).then_some((k, gap * gap))
                })
                .collect();
            let total: f64 = near.iter().map(|&(_, w)| w).sum();
            let j = near
                .iter()
                .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
                .map_or(0, |&(k, _)| k);
            let mut t = theta[j];
            if total > 0.0 {
                for &(k, w) in &near {
                    if let Some(h) = complex.oriented(harmonic, j, k) {
                        t += w / total * h;
                    }
                }
            }
            std::f64::consts::TAU * t.rem_euclid(1.0)
        })
        .collect();
    let mut agreement = BTreeMap::new();
    let mut plane = None;
    if let Some(truth) = truth {
        let linear = truth.space().linear_columns();
        if linear.len() >= 2 {
            let positions = truth.poses().select(Axis(1), &linear[..2]);
            plane = plane_agreement(distances, &values, positions.view());
        }
        let poses = truth.poses();
        for c in truth.space().components() {
            if c.kind == CoordinateKind::Angle {
                let alpha: Vec<f64> = poses.column(c.column).to_vec();
                agreement.insert(c.name, agree(&alpha, &values));
            }
        }
        if truth.space().is_planar() {
            let relative: Vec<f64> = poses
                .rows()
                .into_iter()
                .map(|p| p[2] - p[1].atan2(p[0]))
                .collect();
            agreement.insert(BEARING_RELATIVE.to_owned(), agree(&relative, &values));
        }
    }
    Ok(Some(CircleCoordinate {
        landmarks: l,
        covering_radius: epsilon,
        bar: [birth, death],
        radius,
        scale,
        edges: complex.edges.len(),
        triangles: complex.triangles(),
        classes: cocycle.classes,
        largest_integer: cocycle.values.iter().map(|z| z.abs()).max().unwrap_or(0),
        agreement,
        plane,
        values,
    }))
}

/// The plane at fixed circle coordinate (module docs): in each of [`PLANE_SLICES`]
/// slices of `theta` holding at least [`PLANE_MIN_SETS`] sets, the two leading
/// classical-scaling coordinates of the slice's distances, the `R²` of the positions
/// fitted affinely from them; the median and least over the slices.
fn plane_agreement(
    distances: ArrayView2<'_, f64>,
    theta: &[f64],
    positions: ArrayView2<'_, f64>,
) -> Option<PlaneAgreement> {
    let mut scores = Vec::new();
    let mut sizes = Vec::new();
    for slice in 0..PLANE_SLICES {
        let (low, high) = (
            slice as f64 * std::f64::consts::TAU / PLANE_SLICES as f64,
            (slice + 1) as f64 * std::f64::consts::TAU / PLANE_SLICES as f64,
        );
        let rows: Vec<usize> = (0..theta.len())
            .filter(|&i| theta[i] >= low && theta[i] < high)
            .collect();
        let k = rows.len();
        if k < PLANE_MIN_SETS {
            continue;
        }
        // B = −½ J D² J, its two leading eigenvectors scaled by √λ.
        let d2 = distances
            .select(Axis(0), &rows)
            .select(Axis(1), &rows)
            .mapv(|d| d * d);
        let row_means: Vec<f64> = d2.rows().into_iter().map(|r| r.sum() / k as f64).collect();
        let all = row_means.iter().sum::<f64>() / k as f64;
        let b = faer::Mat::<f64>::from_fn(k, k, |i, j| {
            -0.5 * (d2[[i, j]] - row_means[i] - row_means[j] + all)
        });
        let Ok((values, vectors)) = crate::linalg::self_adjoint_eigen(b.as_ref()) else {
            continue;
        };
        let coordinates = ndarray::Array2::from_shape_fn((k, 2), |(i, c)| {
            let column = k - 1 - c;
            vectors[(i, column)] * values[column].max(0.0).sqrt()
        });
        let slice_positions = positions.select(Axis(0), &rows);
        if let Ok(fit) = super::affine::affine_errors(coordinates.view(), slice_positions.view()) {
            scores.push(fit.r_squared);
            sizes.push(k);
        }
    }
    if scores.is_empty() {
        return None;
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let least = scores.iter().copied().fold(f64::INFINITY, f64::min);
    sizes.sort_unstable();
    Some(PlaneAgreement {
        slices: scores.len(),
        sets_per_slice: sizes[sizes.len() / 2],
        r_squared: median(&mut scores),
        r_squared_min: least,
    })
}

/// Circular correlation and resultant of `alpha` and `beta` (module docs).
pub fn agree(alpha: &[f64], beta: &[f64]) -> CircleAgreement {
    // Fisher–Lee through its sums: with A = Σ cos α cos β, B = Σ sin α sin β,
    // C = Σ cos α sin β, D = Σ sin α cos β and the second moments E, F (of 2α), G, H
    // (of 2β): ρ = 4 (AB − CD) / √((n² − E² − F²)(n² − G² − H²)).
    let n = alpha.len() as f64;
    let (mut a, mut b, mut c, mut d) = (0.0, 0.0, 0.0, 0.0);
    let (mut e, mut f, mut g, mut h) = (0.0, 0.0, 0.0, 0.0);
    for (&x, &y) in alpha.iter().zip(beta) {
        let ((sx, cx), (sy, cy)) = (x.sin_cos(), y.sin_cos());
        a += cx * cy;
        b += sx * sy;
        c += cx * sy;
        d += sx * cy;
        e += (2.0 * x).cos();
        f += (2.0 * x).sin();
        g += (2.0 * y).cos();
        h += (2.0 * y).sin();
    }
    let spread = (n * n - e * e - f * f) * (n * n - g * g - h * h);
    let rho = if spread > 0.0 {
        4.0 * (a * b - c * d) / spread.sqrt()
    } else {
        0.0
    };
    let resultant = |sign: f64| {
        let (s, c) = alpha.iter().zip(beta).fold((0.0, 0.0), |(s, c), (&a, &b)| {
            (s + (a - sign * b).sin(), c + (a - sign * b).cos())
        });
        s.hypot(c) / alpha.len().max(1) as f64
    };
    CircleAgreement {
        circular_correlation: rho.abs(),
        reversed: rho < 0.0,
        resultant: resultant(1.0).max(resultant(-1.0)),
    }
}

/// The Rips 2-complex of the landmarks at one scale: its edges `i < k`, an edge table
/// and sorted neighbour lists.
struct Complex {
    edges: Vec<(u32, u32)>,
    /// `index[i * l + k]`: the edge of `i` and `k` (either order), `u32::MAX` if none.
    index: Vec<u32>,
    neighbours: Vec<Vec<u32>>,
    l: usize,
}

impl Complex {
    fn at(d: ArrayView2<'_, f64>, scale: f64) -> Self {
        let l = d.nrows();
        let mut edges = Vec::new();
        let mut index = vec![u32::MAX; l * l];
        let mut neighbours = vec![Vec::new(); l];
        for i in 0..l {
            for k in i + 1..l {
                if d[[i, k]] <= scale {
                    let e = edges.len() as u32;
                    edges.push((i as u32, k as u32));
                    index[i * l + k] = e;
                    index[k * l + i] = e;
                    neighbours[i].push(k as u32);
                    neighbours[k].push(i as u32);
                }
            }
        }
        Self {
            edges,
            index,
            neighbours,
            l,
        }
    }

    fn edge(&self, i: usize, k: usize) -> Option<usize> {
        let e = self.index[i * self.l + k];
        (e != u32::MAX).then_some(e as usize)
    }

    /// `c_jk` of the cochain `c` on edge `j → k` (`−c` against the edge's order).
    fn oriented(&self, c: &[f64], j: usize, k: usize) -> Option<f64> {
        if j == k {
            return Some(0.0);
        }
        self.edge(j, k).map(|e| if j < k { c[e] } else { -c[e] })
    }

    /// The third vertices `m` of the triangles on edge `(i, k)`: the common neighbours.
    fn common(&self, i: usize, k: usize, mut each: impl FnMut(usize)) {
        let (a, b) = (&self.neighbours[i], &self.neighbours[k]);
        let (mut x, mut y) = (0, 0);
        while x < a.len() && y < b.len() {
            match a[x].cmp(&b[y]) {
                std::cmp::Ordering::Less => x += 1,
                std::cmp::Ordering::Greater => y += 1,
                std::cmp::Ordering::Equal => {
                    each(a[x] as usize);
                    x += 1;
                    y += 1;
                }
            }
        }
    }

    /// Every triangle `i < j < k` as its edges `(ij, jk, ik)`.
    fn for_each_triangle(&self, mut each: impl FnMut(usize, usize, usize)) {
        for (e, &(i, j)) in self.edges.iter().enumerate() {
            let (i, j) = (i as usize, j as usize);
            self.common(i, j, |k| {
                if k > j {
                    let jk = self.edge(j, k).expect("a common neighbour has its edge");
                    let ik = self.edge(i, k).expect("a common neighbour has its edge");
                    each(e, jk, ik);
                }
            });
        }
    }

    fn triangles(&self) -> usize {
        let mut count = 0;
        self.for_each_triangle(|_, _, _| count += 1);
        count
    }
}

fn mul(a: u64, b: u64) -> u64 {
    a * b % PRIME
}

fn neg(a: u64) -> u64 {
    (PRIME - a) % PRIME
}

fn inverse(a: u64) -> u64 {
    let (mut base, mut power, mut out) = (a % PRIME, PRIME - 2, 1);
    while power > 0 {
        if power & 1 == 1 {
            out = mul(out, base);
        }
        base = mul(base, base);
        power >>= 1;
    }
    out
}

/// A linear form in the free parameters, sparse, sorted by parameter.
type Form = Vec<(u32, u64)>;

/// `a + c b`.
fn axpy(a: &Form, c: u64, b: &Form) -> Form {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut x, mut y) = (0, 0);
    while x < a.len() || y < b.len() {
        let (p, v) = match (a.get(x), b.get(y)) {
            (Some(&(pa, va)), Some(&(pb, _))) if pa < pb => {
                x += 1;
                (pa, va)
            }
            (Some(&(pa, va)), Some(&(pb, vb))) if pa == pb => {
                x += 1;
                y += 1;
                (pa, (va + mul(c, vb)) % PRIME)
            }
            (Some(&(pa, va)), None) => {
                x += 1;
                (pa, va)
            }
            (_, Some(&(pb, vb))) => {
                y += 1;
                (pb, mul(c, vb))
            }
            (None, None) => unreachable!(),
        };
        if v != 0 {
            out.push((p, v));
        }
    }
    out
}

/// An integer cocycle of the loop's class, its harmonic smoothing (the landmarks'
/// coordinates and the harmonic cochain) and the dimension of `H¹(K; Z/p)`.
struct IntegerCocycle {
    values: Vec<i64>,
    theta: Vec<f64>,
    harmonic: Vec<f64>,
    classes: usize,
}

/// A spanning tree of the landmarks' 1-skeleton, by breadth-first search from landmark
/// 0: its edges get the zero form, in the order found; an error when the complex is
/// not connected.
fn spanning_tree(complex: &Complex) -> Result<(Vec<Option<Form>>, Vec<usize>), AnalysisError> {
    let mut forms: Vec<Option<Form>> = vec![None; complex.edges.len()];
    let mut seen = vec![false; complex.l];
    let mut queue = std::collections::VecDeque::from([0usize]);
    seen[0] = true;
    let mut order = Vec::new();
    while let Some(i) = queue.pop_front() {
        for &k in &complex.neighbours[i] {
            let k = k as usize;
            if !seen[k] {
                seen[k] = true;
                let e = complex.edge(i, k).expect("a neighbour has its edge");
                forms[e] = Some(Vec::new());
                order.push(e);
                queue.push_back(k);
            }
        }
    }
    if let Some(apart) = seen.iter().position(|s| !s) {
        return Err(AnalysisError::Degenerate {
            what: "the circular coordinate",
            reason: format!(
                "the landmarks' complex at this scale is not connected (landmark {apart} is apart); take more landmarks (circle_landmarks) or a larger circle_scale"
            ),
        });
    }
    Ok((forms, order))
}

/// What the triangles say of the edges once the tree is known: every edge's value as
/// a form in the free parameters, their count, and the constraints left (forms that
/// must vanish).
struct Propagated {
    forms: Vec<Form>,
    parameters: usize,
    constraints: Vec<Form>,
}

/// Propagates the tree's zeros through the triangles (`z_ij + z_jk − z_ik = 0`): an
/// edge that is the last unknown of a triangle gets the form the other two give; when
/// none is, the first unknown edge becomes a free parameter. A triangle whose three
/// edges are known gives a constraint, checked once (when the last of them is popped).
fn propagate(
    complex: &Complex,
    mut forms: Vec<Option<Form>>,
    order: Vec<usize>,
) -> Result<Propagated, AnalysisError> {
    let m = complex.edges.len();
    let mut popped = vec![false; m];
    let mut pending: std::collections::VecDeque<usize> = order.into();
    let mut parameters = 0usize;
    let mut constraints: Vec<Form> = Vec::new();
    let mut next_unknown = 0usize;
    loop {
        while let Some(e) = pending.pop_front() {
            if popped[e] {
                continue;
            }
            popped[e] = true;
            let (a, b) = complex.edges[e];
            let (a, b) = (a as usize, b as usize);
            let mut third = Vec::new();
            complex.common(a, b, |c| third.push(c));
            for c in third {
                let mut v = [a, b, c];
                v.sort_unstable();
                let [i, j, k] = v;
                let ij = complex.edge(i, j).expect("triangle edge");
                let jk = complex.edge(j, k).expect("triangle edge");
                let ik = complex.edge(i, k).expect("triangle edge");
                let unknown = [ij, jk, ik].iter().filter(|&&x| forms[x].is_none()).count();
                match unknown {
                    0 if popped[ij] && popped[jk] && popped[ik] => {
                        let (fij, fjk, fik) = (
                            forms[ij].as_ref().expect("known"),
                            forms[jk].as_ref().expect("known"),
                            forms[ik].as_ref().expect("known"),
                        );
                        let residual = axpy(&axpy(fij, 1, fjk), neg(1), fik);
                        if !residual.is_empty() {
                            constraints.push(residual);
                        }
                    }
                    1 => {
                        let known = |x: usize| forms[x].as_ref().expect("known");
                        let (target, value) = if forms[ik].is_none() {
                            (ik, axpy(known(ij), 1, known(jk)))
                        } else if forms[ij].is_none() {
                            (ij, axpy(known(ik), neg(1), known(jk)))
                        } else {
                            (jk, axpy(known(ik), neg(1), known(ij)))
                        };
                        forms[target] = Some(value);
                        pending.push_back(target);
                    }
                    _ => {}
                }
            }
        }
        while next_unknown < m && forms[next_unknown].is_some() {
            next_unknown += 1;
        }
        if next_unknown == m {
            break;
        }
        if parameters == MAX_PARAMETERS {
            return Err(AnalysisError::TooLarge {
                what: format!(
                    "the circular coordinate's cocycle ({m} edges needed more than {MAX_PARAMETERS} free parameters)"
                ),
                limit: "256 free parameters; take fewer landmarks or another circle_scale",
            });
        }
        forms[next_unknown] = Some(vec![(parameters as u32, 1)]);
        pending.push_back(next_unknown);
        parameters += 1;
    }
    Ok(Propagated {
        forms: forms
            .into_iter()
            .map(|f| f.expect("every edge is known"))
            .collect(),
        parameters,
        constraints,
    })
}

/// The reduced row echelon form over `Z/p` of `constraints` (forms in `parameters`
/// unknowns): its rows and their pivot columns.
fn row_echelon(constraints: &[Form], parameters: usize) -> (Vec<Vec<u64>>, Vec<usize>) {
    let mut rows: Vec<Vec<u64>> = Vec::new();
    let mut pivots: Vec<usize> = Vec::new();
    for c in constraints {
        let mut row = vec![0u64; parameters];
        for &(p, v) in c {
            row[p as usize] = v;
        }
        for (r, &p) in rows.iter().zip(&pivots) {
            let f = row[p];
            if f != 0 {
                let f = neg(f);
                for (x, &y) in row.iter_mut().zip(r) {
                    *x = (*x + mul(f, y)) % PRIME;
                }
            }
        }
        let Some(p) = row.iter().position(|&x| x != 0) else {
            continue;
        };
        let s = inverse(row[p]);
        row.iter_mut().for_each(|x| *x = mul(*x, s));
        for r in rows.iter_mut() {
            let f = r[p];
            if f != 0 {
                let f = neg(f);
                for (x, &y) in r.iter_mut().zip(&row) {
                    *x = (*x + mul(f, y)) % PRIME;
                }
            }
        }
        rows.push(row);
        pivots.push(p);
    }
    (rows, pivots)
}

/// Module docs, step 3: the tree, the propagation, the null space of the constraints
/// (one class per free column), and each class (up to 8) lifted to the integers and
/// smoothed; the one of least harmonic energy.
fn integer_cocycle(complex: &Complex) -> Result<IntegerCocycle, AnalysisError> {
    let degenerate = |reason: String| AnalysisError::Degenerate {
        what: "the circular coordinate",
        reason,
    };
    let (tree, order) = spanning_tree(complex)?;
    let Propagated {
        forms,
        parameters,
        constraints,
    } = propagate(complex, tree, order)?;
    let (rows, pivots) = row_echelon(&constraints, parameters);
    let free: Vec<usize> = (0..parameters).filter(|p| !pivots.contains(p)).collect();
    if free.is_empty() {
        return Err(degenerate(format!(
            "the landmarks' complex at scale has no loop in H1 (its {} edges are all filled); take a smaller circle_scale",
            complex.edges.len()
        )));
    }
    let classes = free.len();
    let mut best: Option<(f64, IntegerCocycle)> = None;
    for &f in free.iter().take(8) {
        let mut x = vec![0u64; parameters];
        x[f] = 1;
        for (r, &p) in rows.iter().zip(&pivots) {
            x[p] = neg(r[f]);
        }
        let values: Vec<u64> = forms
            .iter()
            .map(|form| {
                form.iter()
                    .fold(0, |s, &(p, v)| (s + mul(v, x[p as usize])) % PRIME)
            })
            .collect();
        let Some(lift) = lift(complex, &values) else {
            continue;
        };
        let float: Vec<f64> = lift.iter().map(|&z| z as f64).collect();
        let (theta, harmonic) = harmonic_coordinate(complex, &float)?;
        let energy: f64 = harmonic.iter().map(|h| h * h).sum();
        if best.as_ref().is_none_or(|(e, _)| energy < *e) {
            let found = IntegerCocycle {
                values: lift,
                theta,
                harmonic,
                classes,
            };
            best = Some((energy, found));
        }
    }
    best.map(|(_, found)| found)
        .ok_or_else(|| degenerate("no class of H1(K; Z/p) lifts to an integer cocycle".to_owned()))
}

/// The integer cocycle of least `Σ|z|` among the scalings of `values` that make one of
/// its entries 1, or `None`.
fn lift(complex: &Complex, values: &[u64]) -> Option<Vec<i64>> {
    let mut candidates: Vec<u64> = Vec::new();
    for &v in values {
        if v != 0 && !candidates.contains(&v) {
            candidates.push(v);
            if candidates.len() == 16 {
                break;
            }
        }
    }
    let symmetric = |v: u64| -> i64 {
        if v > PRIME / 2 {
            v as i64 - PRIME as i64
        } else {
            v as i64
        }
    };
    let mut best: Option<(i64, Vec<i64>)> = None;
    for c in candidates {
        let s = inverse(c);
        let z: Vec<i64> = values.iter().map(|&v| symmetric(mul(s, v))).collect();
        if z.iter().any(|x| x.abs() > MAX_LIFT) {
            continue;
        }
        let mut cocycle = true;
        complex.for_each_triangle(|ij, jk, ik| cocycle &= z[ij] + z[jk] - z[ik] == 0);
        if !cocycle {
            continue;
        }
        let norm: i64 = z.iter().map(|x| x.abs()).sum();
        if best.as_ref().is_none_or(|(b, _)| norm < *b) {
            best = Some((norm, z));
        }
    }
    best.map(|(_, z)| z)
}

/// The landmarks' coordinates `θ = −f mod 1` and the harmonic cochain `h = z − δf`
/// of the density-weighted Laplacian (module docs, step 4).
fn harmonic_coordinate(
    complex: &Complex,
    z: &[f64],
) -> Result<(Vec<f64>, Vec<f64>), AnalysisError> {
    let l = complex.l;
    // (Δ_w + 11ᵀ) f = δᵀ W z: the Laplacian of a connected graph plus the constant's
    // projector is positive definite, and the solution has Σ f = 0.
    let mut a = faer::Mat::<f64>::from_fn(l, l, |_, _| 1.0);
    let mut b = vec![0.0; l];
    let degree: Vec<f64> = complex.neighbours.iter().map(|n| n.len() as f64).collect();
    for (e, &(i, k)) in complex.edges.iter().enumerate() {
        let (i, k) = (i as usize, k as usize);
        let w = 1.0 / (degree[i] * degree[k]);
        a[(i, i)] += w;
        a[(k, k)] += w;
        a[(i, k)] -= w;
        a[(k, i)] -= w;
        b[k] += w * z[e];
        b[i] -= w * z[e];
    }
    let mut rhs = faer::Mat::<f64>::from_fn(l, 1, |i, _| b[i]);
    if !crate::linalg::cholesky_solve(a.as_mut(), rhs.as_mut()) {
        return Err(AnalysisError::Degenerate {
            what: "the circular coordinate",
            reason: "the landmarks' graph Laplacian is singular".to_owned(),
        });
    }
    let f: Vec<f64> = (0..l).map(|i| rhs[(i, 0)]).collect();
    let harmonic = complex
        .edges
        .iter()
        .enumerate()
        .map(|(e, &(i, k))| z[e] - (f[k as usize] - f[i as usize]))
        .collect();
    Ok((f.iter().map(|x| (-x).rem_euclid(1.0)).collect(), harmonic))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};

    fn euclidean(points: &[Vec<f64>]) -> Array2<f64> {
        let n = points.len();
        Array2::from_shape_fn((n, n), |(i, j)| {
            points[i]
                .iter()
                .zip(&points[j])
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
        })
    }

    fn params() -> CircleParams {
        CircleParams {
            landmarks: 120,
            scale: 0.5,
        }
    }

    #[test]
    fn a_noisy_annulus_gives_its_angle_back() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut angles = Vec::new();
        let points: Vec<Vec<f64>> = (0..600)
            .map(|_| {
                let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                let r: f64 = rng.random_range(0.8..1.2);
                angles.push(a);
                vec![r * a.cos(), r * a.sin()]
            })
            .collect();
        let d = euclidean(&points);
        let c = circle_coordinate(d.view(), None, &params())
            .unwrap()
            .unwrap();
        assert_eq!(c.classes, 1);
        assert_eq!(c.largest_integer, 1);
        let a = agree(&angles, &c.values);
        assert!(a.circular_correlation > 0.99, "{a:?}");
        assert!(a.resultant > 0.99, "{a:?}");
    }

    #[test]
    fn a_solid_torus_circle_times_a_disc_gives_the_circle() {
        // (cos a, sin a) scaled by 2 plus a disc of radius 0.6 in (radial, z): a
        // circle times a plane, like the arm's manifold.
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut angles = Vec::new();
        let points: Vec<Vec<f64>> = (0..900)
            .map(|_| {
                let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                let (u, v): (f64, f64) = (rng.random_range(-0.6..0.6), rng.random_range(-0.6..0.6));
                angles.push(-a + 1.0);
                let radial = 2.0 + u;
                vec![radial * a.cos(), radial * a.sin(), v]
            })
            .collect();
        let d = euclidean(&points);
        let c = circle_coordinate(d.view(), None, &params())
            .unwrap()
            .unwrap();
        let a = agree(&angles, &c.values);
        // The harmonic coordinate is the angle up to the sampling's unevenness.
        assert!(a.circular_correlation > 0.95, "{a:?}");
        assert!(a.resultant > 0.98, "{a:?}");
    }

    #[test]
    fn a_disc_has_no_circle() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let points: Vec<Vec<f64>> = (0..300)
            .map(|_| vec![rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)])
            .collect();
        let d = euclidean(&points);
        match circle_coordinate(d.view(), None, &params()) {
            // No bar, or only a short one that the landmarks do not resolve, or one
            // with no class at its scale: never a circle that is not there.
            Ok(None) | Err(AnalysisError::Degenerate { .. }) => {}
            Ok(Some(c)) => {
                let spread = c.bar[1] - c.bar[0];
                assert!(spread < 0.2, "a disc read a loop: {c:?}");
            }
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn the_cocycle_of_a_hexagon_of_triangles_is_found_with_one_parameter() {
        // A ring of 12 points: the complex at the neighbours' spacing is a 12-cycle.
        let points: Vec<Vec<f64>> = (0..12)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 12.0;
                vec![a.cos(), a.sin()]
            })
            .collect();
        let d = euclidean(&points);
        let complex = Complex::at(d.view(), 0.6);
        assert_eq!(complex.edges.len(), 12);
        assert_eq!(complex.triangles(), 0);
        let z = integer_cocycle(&complex).unwrap();
        assert_eq!(z.classes, 1);
        assert_eq!(z.values.iter().map(|x| x.abs()).sum::<i64>(), 1);
        let float: Vec<f64> = z.values.iter().map(|&x| x as f64).collect();
        let (theta, h) = harmonic_coordinate(&complex, &float).unwrap();
        // The harmonic cochain spreads the one turn evenly: 1/12 on every edge.
        for (e, &(i, k)) in complex.edges.iter().enumerate() {
            assert!((h[e].abs() - 1.0 / 12.0).abs() < 1e-9, "{h:?}");
            let step = (theta[k as usize] - theta[i as usize] - h[e]).rem_euclid(1.0);
            assert!(!(1e-9..=1.0 - 1e-9).contains(&step));
        }
    }

    #[test]
    fn the_circular_correlation_is_one_for_a_rotation_and_reversed_for_a_reflection() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let alpha: Vec<f64> = (0..500)
            .map(|_| rng.random_range(0.0..std::f64::consts::TAU))
            .collect();
        let turned: Vec<f64> = alpha.iter().map(|a| a + 2.0).collect();
        let mirrored: Vec<f64> = alpha.iter().map(|a| 0.5 - a).collect();
        let unrelated: Vec<f64> = (0..500)
            .map(|_| rng.random_range(0.0..std::f64::consts::TAU))
            .collect();
        let a = agree(&alpha, &turned);
        assert!(
            (a.circular_correlation - 1.0).abs() < 1e-12 && !a.reversed,
            "{a:?}"
        );
        assert!((a.resultant - 1.0).abs() < 1e-12);
        let a = agree(&alpha, &mirrored);
        assert!(
            (a.circular_correlation - 1.0).abs() < 1e-12 && a.reversed,
            "{a:?}"
        );
        let a = agree(&alpha, &unrelated);
        assert!(a.circular_correlation < 0.15 && a.resultant < 0.15, "{a:?}");
    }

    #[test]
    fn bad_parameters_name_their_key() {
        let d = Array2::<f64>::zeros((5, 5));
        let bad = CircleParams {
            landmarks: 2,
            scale: 0.5,
        };
        let e = circle_coordinate(d.view(), None, &bad).unwrap_err();
        assert!(e.to_string().contains("circle_landmarks"), "{e}");
        let bad = CircleParams {
            landmarks: 10,
            scale: 1.0,
        };
        let e = circle_coordinate(d.view(), None, &bad).unwrap_err();
        assert!(e.to_string().contains("circle_scale"), "{e}");
    }
}
