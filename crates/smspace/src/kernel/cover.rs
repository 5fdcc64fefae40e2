//! Kernels of dimension `k ≥ 2` (a dense covering and farthest-point subsampling), and
//! the multi-start search for the pieces of a level set.
//!
//! ## Covering a k-dimensional kernel
//!
//! From a point `m` on the level set, the null space of `J(m)` has an orthonormal basis
//! `b_1 … b_k` ([`LevelSet::null_basis`]). A breadth-first covering expands every node
//! by tangent steps of length `h = cover_step`: `m + h Σ_j c_j b_j` for the unit
//! directions `c` of a lattice (for `k = 2` the six directions at 60°, a hexagonal
//! lattice; otherwise `±e_j`), each projected back onto the level set by the corrector
//! (Newton with minimum-norm steps, the same as for curves, to the pose or sensor
//! tolerance). A projected candidate is kept when no node lies within `0.7 h` of it
//! (torus distance: periodic coordinates wrapped), so nodes are at least `0.7 h`
//! apart and every point of the kernel reached by the expansion is within about `h`
//! of a node. A step that leaves the range of a bounded motor is dropped (the covering
//! stops at the range). Nodes are found in a fixed order (breadth first, directions in
//! a fixed order), so the covering is deterministic.
//!
//! A covering costs sensor rows in proportion to its nodes (a linearisation and a
//! corrector run per lattice direction each). Before any set is covered, the nodes
//! are forecast as `∏ (range_j / h)` over the `k` widest motor ranges (a kernel that
//! spans them); a forecast beyond [`FORECAST_MARGIN`] times `max_cover_points` fails
//! every set at once as `cover-budget`, without reading a sensor for the covering,
//! instead of covering `max_cover_points` nodes first (for a 3-D kernel of hinges at
//! the default step, 2·10⁶ nodes forecast against 10⁵ allowed).
//!
//! ## Farthest-point subsampling and the covering radius
//!
//! `P` nodes are picked farthest first from the start `m⁰` (ties to the lowest node):
//! each next point is the node farthest from those already picked. The largest
//! distance from a node of the covering to its nearest pick is the set's **covering
//! radius** `ε` (reported per set): every point of the kernel lies within `ε` plus the
//! covering's own spacing (about `h`) of a sample. For two sets `A ⊂ K_A`, `B ⊂ K_B`
//! with covering radii `ε_A`, `ε_B`, the triangle inequality gives
//! `|ρ(A, B) − ρ(K_A, K_B)| ≤ max(ε_A, ε_B) ≤ ε_A + ε_B` for the Hausdorff distance `ρ`.
//!
//! ## Pieces (multi-start)
//!
//! A level set may have several connected pieces (the elbow-up and elbow-down
//! self-motions of a 3-link arm whose retina is closer than one link to the base,
//! paper appendix A). The seeds of the search are the first `piece_starts` points of
//! the Halton sequence (bases 2, 3, 5, …) shifted by a random vector drawn from
//! `ChaCha8(piece_seed)` (a Cranley–Patterson rotation), mapped onto the range of
//! every motor: the same seeds for every set. Each seed is projected onto the level set
//! by damped Gauss–Newton steps (minimum-norm, at most `0.5` rad each), given up when
//! 8 iterations in a row do not halve its smallest residual yet; a projected
//! seed farther than `piece_tolerance` from every piece found (from the traced curve,
//! or `1.5 cover_step + piece_tolerance` from the covering's nodes) starts a new piece.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use rand::{RngExt, SeedableRng};

use super::curve::{correct, Convergence, Scratch};
use super::level_set::LevelSet;
use super::params::rows_spent;
use super::SetStatus;
use crate::agent::{Motor, MotorSpace};

/// A candidate is kept when no node lies within this fraction of the step.
const ACCEPT_FRACTION: f64 = 0.7;
/// A prediction within this fraction of the step of a node is not projected.
const PREDICTED_FRACTION: f64 = 0.5;
/// Longest damped Gauss–Newton step of the multi-start projection, radians.
const MAX_SEED_STEP: f64 = 0.5;
/// A covering forecast at more than this many times `max_cover_points` nodes is not
/// started ([`forecast_nodes`]).
pub(crate) const FORECAST_MARGIN: f64 = 10.0;
/// Iterations of the multi-start projection.
const SEED_ITERATIONS: usize = 60;
/// A seed's projection gives up after this many iterations that did not halve the
/// smallest residual yet seen (a local minimum of `‖s(m) − s⁰‖` off the level set,
/// or a region the sensors cannot tell apart), where it would take all
/// [`SEED_ITERATIONS`] to fail.
const SEED_STALL: usize = 8;

/// A small multiplicative hasher for the grid's integer cell keys (deterministic,
/// unlike the standard library's random state).
#[derive(Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
    fn write_i64(&mut self, v: i64) {
        self.write_u64(v as u64);
    }
}

/// How one motor coordinate is cut into grid cells.
#[derive(Debug, Clone, Copy)]
struct Axis {
    low: f64,
    width: f64,
    count: i64,
    periodic: bool,
}

/// A uniform grid over the first (at most three) motor coordinates, cells at least
/// the search radius wide (periodic coordinates: a whole number of cells per
/// period), for the nearest-node queries of the covering.
pub(crate) struct Grid {
    axes: Vec<Axis>,
    cells: HashMap<[i64; 3], Vec<u32>, BuildHasherDefault<CellHasher>>,
}

impl Grid {
    /// A grid for queries within `radius` in `space`.
    pub(crate) fn new(space: &MotorSpace, radius: f64) -> Self {
        let axes = space
            .motors()
            .iter()
            .take(3)
            .map(|&motor| {
                let (low, high) = motor.range();
                let span = high - low;
                let count = ((span / radius).floor() as i64).max(1);
                Axis {
                    low,
                    width: span / count as f64,
                    count,
                    periodic: matches!(motor, Motor::Periodic { .. }),
                }
            })
            .collect();
        Self {
            axes,
            cells: HashMap::default(),
        }
    }

    fn cell(&self, m: &[f64]) -> [i64; 3] {
        let mut key = [0i64; 3];
        for (j, axis) in self.axes.iter().enumerate() {
            let i = ((m[j] - axis.low) / axis.width).floor() as i64;
            key[j] = if axis.periodic {
                i.rem_euclid(axis.count)
            } else {
                i.clamp(0, axis.count - 1)
            };
        }
        key
    }

    /// Adds node `index` at (wrapped) `m`.
    pub(crate) fn insert(&mut self, index: usize, m: &[f64]) {
        let key = self.cell(m);
        self.cells.entry(key).or_default().push(index as u32);
    }

    /// Calls `visit` with every node in the cells around `m` (every node within the
    /// grid's radius is among them); stops early when `visit` returns `true`.
    pub(crate) fn any_near(&self, m: &[f64], mut visit: impl FnMut(usize) -> bool) -> bool {
        let centre = self.cell(m);
        let dims = self.axes.len();
        let mut offsets = [0i64; 3];
        let total = 3usize.pow(dims as u32);
        let mut seen: [[i64; 3]; 27] = [[i64::MIN; 3]; 27];
        for code in 0..total {
            let mut c = code;
            for o in offsets.iter_mut().take(dims) {
                *o = (c % 3) as i64 - 1;
                c /= 3;
            }
            let mut key = [0i64; 3];
            let mut inside = true;
            for (j, axis) in self.axes.iter().enumerate() {
                let i = centre[j] + offsets[j];
                key[j] = if axis.periodic {
                    i.rem_euclid(axis.count)
                } else {
                    inside &= (0..axis.count).contains(&i);
                    i
                };
            }
            // A period of fewer than three cells visits a cell twice otherwise.
            if !inside || seen[..code].contains(&key) {
                continue;
            }
            seen[code] = key;
            if let Some(nodes) = self.cells.get(&key) {
                if nodes.iter().any(|&i| visit(i as usize)) {
                    return true;
                }
            }
        }
        false
    }
}

/// The unit directions of the covering's lattice in the tangent coordinates: six at
/// 60° for `k = 2`, `±e_j` otherwise (`k × count`, row per direction).
fn lattice_directions(k: usize) -> Vec<Vec<f64>> {
    if k == 2 {
        return (0..6)
            .map(|l| {
                let angle = std::f64::consts::FRAC_PI_3 * l as f64;
                vec![angle.cos(), angle.sin()]
            })
            .collect();
    }
    let mut out = Vec::with_capacity(2 * k);
    for j in 0..k {
        for sign in [1.0, -1.0] {
            let mut c = vec![0.0; k];
            c[j] = sign;
            out.push(c);
        }
    }
    out
}

/// The nodes of a covering: wrapped points on the level set, with the piece of each.
#[derive(Debug, Default)]
pub(crate) struct Covering {
    /// Nodes, `N` values each, periodic coordinates wrapped.
    pub nodes: Vec<f64>,
    /// The piece of every node.
    pub piece: Vec<usize>,
    /// Largest corrector residual over the nodes.
    pub max_residual: f64,
}

/// The covering's settings.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CoverSettings {
    /// Tangent step `h`.
    pub step: f64,
    /// Most nodes of one set (all pieces).
    pub max_nodes: usize,
    /// Corrector iterations per node.
    pub max_iterations: usize,
    /// Most sensor rows of one set (0: no cap).
    pub max_rows: u64,
    /// Kernel dimension `k`.
    pub dimension: usize,
}

/// Adds the piece through `start` (a point on the level set) to `covering`,
/// breadth first from `start` (see the module docs). Fails with
/// [`SetStatus::CoverBudget`] beyond `max_nodes` nodes, and with
/// [`SetStatus::RowBudget`] once the set has read `max_rows` sensor rows.
pub(crate) fn cover_piece(
    set: &mut dyn LevelSet,
    start: &[f64],
    space: &MotorSpace,
    settings: &CoverSettings,
    grid: &mut Grid,
    covering: &mut Covering,
    scratch: &mut Scratch,
) -> Result<(), SetStatus> {
    let n = start.len();
    scratch.prepare(set.rows(), n);
    let k = settings.dimension;
    let h = settings.step;
    let accept = ACCEPT_FRACTION * h;
    let piece = covering.piece.last().map_or(0, |&p| p + 1);
    let directions = lattice_directions(k);
    let mut first = start.to_vec();
    space.wrap_points(&mut first);
    let mut queue = covering.nodes.len() / n;
    grid.insert(queue, &first);
    covering.nodes.extend_from_slice(&first);
    covering.piece.push(piece);
    let mut basis = vec![0.0; k * n];
    let mut candidate = vec![0.0; n];
    let mut r = vec![0.0; set.rows()];
    while queue < covering.nodes.len() / n {
        let node = covering.nodes[queue * n..(queue + 1) * n].to_vec();
        queue += 1;
        if set.linearize(&node, &mut r).is_err() {
            continue;
        }
        set.null_basis(k, &mut basis);
        for c in &directions {
            for j in 0..n {
                candidate[j] = node[j] + h * (0..k).map(|a| c[a] * basis[a * n + j]).sum::<f64>();
            }
            // A prediction already close to a node would be dropped after its
            // projection too (the corrector moves it by O(h²)): skip the corrector.
            space.wrap_points(&mut candidate);
            let nodes = &covering.nodes;
            if grid.any_near(&candidate, |i| {
                space.distance(&nodes[i * n..(i + 1) * n], &candidate) < PREDICTED_FRACTION * h
            }) {
                continue;
            }
            if !set.newton() && set.linearize(&node, &mut r).is_err() {
                continue;
            }
            let Some(corrected) = correct(
                set,
                &mut candidate,
                scratch,
                settings.max_iterations,
                Convergence::Measured,
            ) else {
                continue;
            };
            if outside_bounds(space, &candidate) {
                continue;
            }
            space.wrap_points(&mut candidate);
            let nodes = &covering.nodes;
            let near = grid.any_near(&candidate, |i| {
                space.distance(&nodes[i * n..(i + 1) * n], &candidate) < accept
            });
            if near {
                continue;
            }
            let index = covering.nodes.len() / n;
            if index >= settings.max_nodes {
                return Err(SetStatus::CoverBudget);
            }
            if rows_spent(settings.max_rows, set.sensor_rows()) {
                return Err(SetStatus::RowBudget);
            }
            grid.insert(index, &candidate);
            covering.nodes.extend_from_slice(&candidate);
            covering.piece.push(piece);
            covering.max_residual = covering.max_residual.max(corrected.residual);
        }
    }
    Ok(())
}

/// The forecast of a covering's nodes before any is made: a `k`-dimensional kernel
/// spanning the ranges of `k` motors (the `k` widest) needs about `∏ (range_j / h)`
/// nodes at the covering's spacing `h`. A kernel set smaller than that needs fewer,
/// one that winds round a period several times more.
pub(crate) fn forecast_nodes(space: &MotorSpace, k: usize, step: f64) -> f64 {
    let mut ranges: Vec<f64> = space
        .motors()
        .iter()
        .map(|motor| {
            let (low, high) = motor.range();
            high - low
        })
        .collect();
    ranges.sort_by(|a, b| b.total_cmp(a));
    ranges.iter().take(k).map(|range| range / step).product()
}

/// Whether a bounded coordinate of `m` is outside its range.
fn outside_bounds(space: &MotorSpace, m: &[f64]) -> bool {
    space
        .motors()
        .iter()
        .zip(m)
        .any(|(motor, &x)| match *motor {
            Motor::Bounded { low, high } => x < low || x > high,
            Motor::Periodic { .. } => false,
        })
}

/// Farthest-first picks of `count` nodes among `nodes` (`N` values each) starting at
/// node `first`, and the covering radius: the largest distance from a node to its
/// nearest pick. With fewer nodes than `count`, the picks cycle through them.
pub(crate) fn farthest_points(
    space: &MotorSpace,
    nodes: &[f64],
    n: usize,
    first: usize,
    count: usize,
) -> (Vec<usize>, f64) {
    let total = nodes.len() / n;
    let node = |i: usize| &nodes[i * n..(i + 1) * n];
    let mut nearest = vec![f64::INFINITY; total];
    let mut picks = Vec::with_capacity(count);
    let mut next = first;
    for _ in 0..count.min(total) {
        picks.push(next);
        let picked = node(next);
        let mut best = (f64::NEG_INFINITY, 0);
        for (i, d) in nearest.iter_mut().enumerate() {
            *d = d.min(space.distance(node(i), picked));
            if *d > best.0 {
                best = (*d, i);
            }
        }
        next = best.1;
    }
    let radius = nearest.iter().fold(0.0, |a: f64, &d| a.max(d));
    let distinct = picks.len();
    for i in distinct..count {
        picks.push(picks[i % distinct.max(1)]);
    }
    (picks, if total == 0 { 0.0 } else { radius })
}

/// The seeds of the multi-start search (see the module docs): `count` points of the
/// shifted Halton sequence mapped onto the motor ranges, `N` values each.
pub(crate) fn piece_seeds(space: &MotorSpace, count: usize, seed: u64) -> Vec<f64> {
    let n = space.dim();
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let shift: Vec<f64> = (0..n).map(|_| rng.random_range(0.0..1.0)).collect();
    let bases = primes(n);
    let mut out = Vec::with_capacity(count * n);
    for i in 0..count {
        for (j, motor) in space.motors().iter().enumerate() {
            let u = (radical_inverse(i as u64 + 1, bases[j]) + shift[j]).fract();
            let (low, high) = motor.range();
            out.push(low + u * (high - low));
        }
    }
    out
}

/// The first `n` primes.
fn primes(n: usize) -> Vec<u64> {
    let mut out = Vec::with_capacity(n);
    let mut candidate = 2u64;
    while out.len() < n {
        if out.iter().all(|&p| !candidate.is_multiple_of(p)) {
            out.push(candidate);
        }
        candidate += 1;
    }
    out
}

/// The van der Corput radical inverse of `i` in `base`.
fn radical_inverse(mut i: u64, base: u64) -> f64 {
    let mut inverse = 0.0;
    let mut factor = 1.0 / base as f64;
    while i > 0 {
        inverse += (i % base) as f64 * factor;
        i /= base;
        factor /= base as f64;
    }
    inverse
}

/// Where the projection of a seed ended ([`project_seed`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Landing {
    /// On the level set, within its tolerance.
    OnSet,
    /// Settling next to a piece already found: stopped early.
    Known,
    /// Nowhere: the projection failed.
    Lost,
}

/// Projects `m` onto the level set from anywhere by damped Gauss–Newton steps
/// (minimum-norm, at most [`MAX_SEED_STEP`] long): [`Landing::OnSet`] when it arrived
/// within the level set's tolerance. Bounded coordinates are clamped into their ranges
/// after every step; it gives up after [`SEED_STALL`] iterations that did not halve
/// the smallest residual seen. Once an undamped step is at most `settle` long and the point it
/// leads to is `known` (next to a piece already found), the projection stops there
/// with [`Landing::Known`]: the remaining steps would move it by a fraction of that
/// step, onto the known piece, and only a new piece matters to the search.
pub(crate) fn project_seed(
    set: &mut dyn LevelSet,
    m: &mut [f64],
    space: &MotorSpace,
    (r, delta): (&mut [f64], &mut [f64]),
    settle: f64,
    known: &mut dyn FnMut(&[f64]) -> bool,
) -> Landing {
    let mut best = f64::INFINITY;
    let mut since_best = 0;
    for _ in 0..SEED_ITERATIONS {
        if set.linearize(m, r).is_err() {
            return Landing::Lost;
        }
        let residual = set.residual_norm(r);
        if !residual.is_finite() {
            return Landing::Lost;
        }
        if residual <= set.tolerance() {
            return Landing::OnSet;
        }
        if residual < 0.5 * best {
            (best, since_best) = (residual, 0);
        } else {
            since_best += 1;
            if since_best >= SEED_STALL {
                return Landing::Lost;
            }
        }
        set.correction(r, delta);
        let length = delta.iter().map(|x| x * x).sum::<f64>().sqrt();
        let scale = if length > MAX_SEED_STEP {
            MAX_SEED_STEP / length
        } else {
            1.0
        };
        for ((x, d), motor) in m.iter_mut().zip(delta.iter()).zip(space.motors()) {
            *x -= scale * d;
            if let Motor::Bounded { low, high } = *motor {
                *x = x.clamp(low, high);
            }
        }
        if length <= settle && known(m) {
            return Landing::Known;
        }
    }
    Landing::Lost
}

/// Shares `total` points among pieces in proportion to their sizes (largest
/// remainders, ties to the earlier piece), each piece at least `minimum[i]`.
pub(crate) fn share_points(total: usize, sizes: &[f64], minimum: &[usize]) -> Vec<usize> {
    let floor: usize = minimum.iter().sum();
    let free = total.saturating_sub(floor);
    let sum: f64 = sizes.iter().sum();
    let exact: Vec<f64> = sizes
        .iter()
        .map(|&s| {
            if sum > 0.0 {
                free as f64 * s / sum
            } else {
                free as f64 / sizes.len() as f64
            }
        })
        .collect();
    let mut counts: Vec<usize> = exact.iter().map(|&e| e.floor() as usize).collect();
    let mut left = free - counts.iter().sum::<usize>().min(free);
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by(|&a, &b| {
        let (ra, rb) = (exact[a] - exact[a].floor(), exact[b] - exact[b].floor());
        rb.total_cmp(&ra).then(a.cmp(&b))
    });
    for &i in order.iter().cycle().take(sizes.len() * 2) {
        if left == 0 {
            break;
        }
        counts[i] += 1;
        left -= 1;
    }
    counts.iter().zip(minimum).map(|(c, m)| c + m).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_are_shared_in_proportion_to_size() {
        assert_eq!(share_points(10, &[3.0, 1.0], &[1, 1]), vec![7, 3]);
        assert_eq!(share_points(200, &[1.0], &[2]), vec![200]);
        let counts = share_points(100, &[1.0, 1.0, 1.0], &[2, 2, 2]);
        assert_eq!(counts.iter().sum::<usize>(), 100);
        assert_eq!(counts, vec![34, 33, 33]);
    }

    #[test]
    fn the_seeds_fill_the_motor_ranges() {
        let space = MotorSpace::hinges(4);
        let seeds = piece_seeds(&space, 64, 3);
        assert_eq!(seeds.len(), 256);
        assert!(seeds
            .iter()
            .all(|x| (-std::f64::consts::PI..std::f64::consts::PI).contains(x)));
        // Every quarter of every coordinate holds some seeds.
        for j in 0..4 {
            for q in 0..4 {
                let low = -std::f64::consts::PI + q as f64 * std::f64::consts::FRAC_PI_2;
                let hits = seeds
                    .chunks(4)
                    .filter(|s| (low..low + std::f64::consts::FRAC_PI_2).contains(&s[j]))
                    .count();
                assert!(hits >= 8, "coordinate {j}, quarter {q}: {hits}");
            }
        }
        assert_eq!(seeds, piece_seeds(&space, 64, 3));
        assert_ne!(seeds, piece_seeds(&space, 64, 4));
    }

    #[test]
    fn farthest_points_report_the_largest_gap() {
        // Points 0, 1, …, 10 on a line (a bounded motor): picks 0, 10, 5 leave every
        // node within 2 of a pick (nodes 2, 3, 7, 8 at exactly 2).
        let space = MotorSpace::bounded(1, -100.0, 100.0).unwrap();
        let nodes: Vec<f64> = (0..=10).map(f64::from).collect();
        let (picks, radius) = farthest_points(&space, &nodes, 1, 0, 3);
        assert_eq!(picks, vec![0, 10, 5]);
        assert!((radius - 2.0).abs() < 1e-12);
        let (cycled, _) = farthest_points(&space, &nodes[..2], 1, 0, 5);
        assert_eq!(cycled, vec![0, 1, 0, 1, 0]);
    }
}
