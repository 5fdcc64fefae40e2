//! Edge collapse of a filtered flag complex, preserving its persistent homology exactly.
//!
//! In a graph `G`, an edge `uv` is *dominated* by a vertex `c ∉ {u, v}` when every
//! common neighbour of `u` and `v` is `c` or a neighbour of `c`
//! (`N[u] ∩ N[v] ⊆ N[c]`, closed neighbourhoods). Removing a dominated edge from a
//! flag complex is a sequence of elementary strong collapses, so the homology does not
//! change (Boissonnat & Pritam, "Edge collapse and persistence of flag complexes",
//! SoCG 2020).
//!
//! For a filtration this is applied as in Glisse & Pritam ("Swap, shift and trim to
//! edge collapse a filtration", SoCG 2022): the edges are taken from the last to the
//! first; an edge `uv` of value `t` that is dominated in the graph of the values
//! `≤ t` (the earlier edges with their input values, the later ones with their
//! already shifted values) is shifted to the first value at which it stops being
//! dominated, and removed when it stays dominated up to the end. Every shift keeps
//! the persistence diagrams (all dimensions) unchanged, and every new value is the
//! value of another edge, so the bars of the collapsed flag filtration are exactly
//! those of the input (zero-length bars aside).
//!
//! The graph is held as a dense matrix of edge values (`∞` for no edge), which makes
//! the domination test a row lookup per common neighbour.

/// The collapsed filtered graph on `n` vertices.
pub(super) struct CollapsedGraph {
    /// Edge values, row-major `n × n`: `∞` where there is no edge, 0 on the diagonal.
    pub values: Vec<f64>,
    /// Neighbours of every vertex, in decreasing order.
    pub neighbors: Vec<Vec<u32>>,
}

/// Collapses the flag filtration of the edges of `dist` (`n × n`, row-major) of value
/// at most `threshold`.
pub(super) fn collapse_edges(n: usize, dist: &[f64], threshold: f64, cut: f64) -> CollapsedGraph {
    let mut values: Vec<f64> = dist
        .iter()
        .map(|&d| if d <= threshold { d } else { f64::INFINITY })
        .collect();
    // The closed neighbourhood: every vertex is its own neighbour from the start.
    for i in 0..n {
        values[i * n + i] = f64::NEG_INFINITY;
    }
    let mut neighbors: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut edges: Vec<(f64, u32, u32)> = Vec::new();
    for u in 0..n {
        for v in 0..n {
            if u != v && values[u * n + v] < f64::INFINITY {
                neighbors[u].push(v as u32);
                if u < v {
                    edges.push((values[u * n + v], u as u32, v as u32));
                }
            }
        }
    }
    // Last edge first (ties: larger vertex pair first, for a fixed order).
    edges.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then((b.2, b.1).cmp(&(a.2, a.1))));

    let mut common: Vec<u32> = Vec::new();
    let mut later: Vec<(f64, u32)> = Vec::new();
    for &(input, u, v) in &edges {
        let (u, v) = (u as usize, v as usize);
        // Scan the shorter neighbour list, dropping the neighbours removed since.
        let (a, b) = if neighbors[u].len() <= neighbors[v].len() {
            (u, v)
        } else {
            (v, u)
        };
        common.clear();
        later.clear();
        let mut best = (f64::INFINITY, usize::MAX);
        {
            let row_a = &values[a * n..(a + 1) * n];
            let row_b = &values[b * n..(b + 1) * n];
            neighbors[a].retain(|&w| {
                let w = w as usize;
                let fa = row_a[w];
                if fa == f64::INFINITY {
                    return false;
                }
                if w != b {
                    let f = fa.max(row_b[w]);
                    if f <= input {
                        common.push(w as u32);
                        if f < best.0 {
                            best = (f, common.len() - 1);
                        }
                    } else if f < f64::INFINITY {
                        later.push((f, w as u32));
                    }
                }
                true
            });
        }
        // The nearest common neighbour is the likeliest dominator: try it first.
        if best.1 != usize::MAX {
            common.swap(0, best.1);
        }
        let mut time = input;
        let mut sorted = false;
        let mut dead = false;
        'search: while let Some(c) = common
            .iter()
            .map(|&c| c as usize)
            .find(|&c| dominates(&values[c * n..(c + 1) * n], &common, time))
        {
            // `c` dominates until a new common neighbour that is not its neighbour
            // appears; then look for another dominator.
            if !sorted {
                later.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
                sorted = true;
            }
            let row_c = &values[c * n..(c + 1) * n];
            loop {
                let Some(&(next, _)) = later.last() else {
                    dead = true;
                    break 'search;
                };
                time = next;
                let mut still = true;
                while let Some(&(f, w)) = later.last() {
                    if f > time {
                        break;
                    }
                    later.pop();
                    if row_c[w as usize] > time {
                        still = false;
                    }
                    common.push(w);
                }
                if !still {
                    break;
                }
            }
        }
        if dead {
            values[u * n + v] = f64::INFINITY;
            values[v * n + u] = f64::INFINITY;
        } else if time != input {
            values[u * n + v] = time;
            values[v * n + u] = time;
        }
    }

    for i in 0..n {
        values[i * n + i] = 0.0;
    }
    for x in values.iter_mut() {
        if *x > cut {
            *x = f64::INFINITY;
        }
    }
    for (i, list) in neighbors.iter_mut().enumerate() {
        list.clear();
        let row = &values[i * n..(i + 1) * n];
        list.extend(
            (0..n)
                .rev()
                .filter(|&j| j != i && row[j] < f64::INFINITY)
                .map(|j| j as u32),
        );
    }
    CollapsedGraph { values, neighbors }
}

/// Whether the vertex of row `row_c` is adjacent, at `time`, to every vertex of
/// `common` (itself included: the diagonal is `−∞`).
#[inline]
fn dominates(row_c: &[f64], common: &[u32], time: f64) -> bool {
    common.iter().all(|&w| row_c[w as usize] <= time)
}
