//! Every Gaussian's nearest neighbours in space: the graph segment consensus clusters, and
//! the neighbourhood every method breaks its ties over.
//!
//! Why a k-d tree and not a uniform grid: a trained 3DGS scene is dense where its subject is
//! and sparse far out (background Gaussians hundreds of times further than the subject's
//! size). A grid sized by the bounding box puts the subject into a handful of cells of
//! thousands of Gaussians each, and every search there scans them all: 200,000 Gaussians
//! on a unit sphere with 2,000 more scattered 2 to 102 units out took 167 s on two cores,
//! against 0.4 s without the 2,000 (docs/robustness-log.md, "Neighbours in scenes of many
//! scales"). The tree splits where the Gaussians are, so its leaves hold a few each at any
//! density, and the search is exact at any distance.

use crate::contract::NO_NEIGHBOUR;
use crate::util::{parallel_map, split_parts, take_part};

/// The `k` nearest other Gaussians of each (by center distance, ties by index), [n][k]
/// row-major, `NO_NEIGHBOUR` where fewer exist.
pub fn nearest_neighbours(means: &[[f32; 3]], k: usize) -> Vec<u32> {
    SpaceTree::new(means).neighbours(k)
}

/// Gaussians per work item of [`SpaceTree::neighbours`].
const QUERY_BLOCK: usize = 4096;

/// Gaussians per leaf at most.
const LEAF: usize = 8;

/// Squared center distance, in f64: the ordering every search here agrees on.
fn dist2(a: [f32; 3], b: [f32; 3]) -> f64 {
    (0..3).map(|i| (a[i] as f64 - b[i] as f64).powi(2)).sum()
}

/// The `k` nearest found so far, nearest first (ties by index).
struct Nearest {
    k: usize,
    found: Vec<(f64, u32)>,
}

impl Nearest {
    fn new(k: usize) -> Nearest {
        Nearest {
            k,
            found: Vec::with_capacity(k + 1),
        }
    }

    /// Whether a Gaussian at distance `d` numbered `h` would be among the nearest (or, for a
    /// node's box and least number, whether one in it might).
    fn takes(&self, d: f64, h: u32) -> bool {
        self.found.len() < self.k || {
            let (worst, number) = self.found[self.k - 1];
            d.total_cmp(&worst).then(h.cmp(&number)).is_lt()
        }
    }

    fn offer(&mut self, d: f64, h: u32) {
        if self.takes(d, h) {
            let nearer = |e: &(f64, u32)| e.0.total_cmp(&d).then(e.1.cmp(&h)).is_lt();
            self.found
                .insert(self.found.partition_point(nearer), (d, h));
            self.found.truncate(self.k);
        }
    }
}

/// A k-d tree over the Gaussians' centers: each node a range of [`SpaceTree::order`], split
/// at its median along its box's longest axis.
struct SpaceTree {
    /// The Gaussians, leaf by leaf: each node's a contiguous range.
    order: Vec<u32>,
    /// Their centers in that order: a leaf's scan reads one run of memory.
    centers: Vec<[f32; 3]>,
    nodes: Vec<Node>,
}

#[derive(Clone, Copy)]
struct Node {
    /// The box of its Gaussians' centers.
    lo: [f32; 3],
    hi: [f32; 3],
    /// Its Gaussians: `order[start..end]`.
    start: u32,
    end: u32,
    /// The least scene index among them.
    least: u32,
    /// Its two children's index (`first`, `first + 1`); 0 for a leaf.
    first: u32,
}

impl SpaceTree {
    fn new(means: &[[f32; 3]]) -> SpaceTree {
        let n = means.len();
        let mut entries: Vec<Entry> = means.iter().copied().zip(0..n as u32).collect();
        let mut nodes = vec![Node::over(&entries, 0)];
        // The top levels here, then the pieces under them on every core (the same tree).
        let mut pieces = split_down(&mut entries, &mut nodes, 0, (n / 64).max(LEAF));
        pieces.sort_by_key(|&i| nodes[i].start);
        // `entries` in parts: each piece's range, and the leaves between pieces.
        let mut lens = vec![];
        let mut at = 0;
        for &i in &pieces {
            let (start, end) = (nodes[i].start as usize, nodes[i].end as usize);
            lens.extend([start - at, end - start]);
            at = end;
        }
        let parts = split_parts(&mut entries, lens);
        let subtrees = parallel_map(pieces.len(), |p| {
            let mut sub = vec![nodes[pieces[p]]];
            split_down(&mut take_part(&parts[2 * p + 1]), &mut sub, 0, 0);
            sub
        });
        drop(parts);
        for (&i, sub) in pieces.iter().zip(subtrees) {
            // The piece's node j (its root 0 stays at i) goes to base + j.
            let base = nodes.len() as u32 - 1;
            let relink = |node: Node| Node {
                first: if node.first == 0 {
                    0
                } else {
                    node.first + base
                },
                ..node
            };
            nodes[i] = relink(sub[0]);
            nodes.extend(sub[1..].iter().map(|&node| relink(node)));
        }
        SpaceTree {
            order: entries.iter().map(|&(_, g)| g).collect(),
            centers: entries.iter().map(|&(m, _)| m).collect(),
            nodes,
        }
    }

    /// [`nearest_neighbours`].
    fn neighbours(&self, k: usize) -> Vec<u32> {
        let n = self.order.len();
        let mut knn = vec![NO_NEIGHBOUR; n * k];
        if n < 2 || k == 0 {
            return knn;
        }
        // Queried in the tree's order, so consecutive queries visit the same leaves whatever
        // order the scene lists its Gaussians in; blocks on every core.
        let blocks = parallel_map(n.div_ceil(QUERY_BLOCK), |b| {
            let places = b * QUERY_BLOCK..n.min((b + 1) * QUERY_BLOCK);
            let mut rows = Vec::with_capacity(places.len() * k);
            let mut best = Nearest::new(k);
            for p in places {
                best.found.clear();
                self.search(0, p, &mut best);
                rows.extend(best.found.iter().map(|&(_, h)| h));
                rows.resize(rows.len() + k - best.found.len(), NO_NEIGHBOUR);
            }
            rows
        });
        for (p, row) in blocks.iter().flat_map(|rows| rows.chunks(k)).enumerate() {
            let g = self.order[p] as usize;
            knn[g * k..(g + 1) * k].copy_from_slice(row);
        }
        knn
    }

    /// Offers `best` every Gaussian of node `i` (but the one at place `p` of the order) that
    /// may be among the nearest to the one at `p`: the nearer child first, a child skipped
    /// when neither its box's distance nor, at the k-th's distance, its least number lets
    /// it hold a nearer one (so many Gaussians at one position cost a few leaves, not all).
    fn search(&self, i: usize, p: usize, best: &mut Nearest) {
        let (node, q) = (&self.nodes[i], self.centers[p]);
        if node.first == 0 {
            for h in node.start as usize..node.end as usize {
                if h != p {
                    best.offer(dist2(q, self.centers[h]), self.order[h]);
                }
            }
            return;
        }
        let (a, b) = (node.first as usize, node.first as usize + 1);
        let (da, db) = (self.box_dist2(a, q), self.box_dist2(b, q));
        let nearer_first = if da <= db {
            [(a, da), (b, db)]
        } else {
            [(b, db), (a, da)]
        };
        for (child, d) in nearer_first {
            if best.takes(d, self.nodes[child].least) {
                self.search(child, p, best);
            }
        }
    }

    /// A lower bound of [`dist2`] from `q` to any center in node `i`'s box: the same sum of
    /// squares in the same order, each term no larger, so no rounding makes it exceed it.
    fn box_dist2(&self, i: usize, q: [f32; 3]) -> f64 {
        let node = &self.nodes[i];
        (0..3)
            .map(|a| {
                let (q, lo, hi) = (q[a] as f64, node.lo[a] as f64, node.hi[a] as f64);
                (lo - q).max(q - hi).max(0.0).powi(2)
            })
            .sum()
    }
}

/// A Gaussian's center and index: what the tree sorts.
type Entry = ([f32; 3], u32);

impl Node {
    /// A leaf over `entries`, the tree's order from place `start`, its box measured.
    fn over(entries: &[Entry], start: usize) -> Node {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        let mut least = u32::MAX;
        for &(m, g) in entries {
            least = least.min(g);
            for i in 0..3 {
                lo[i] = lo[i].min(m[i]);
                hi[i] = hi[i].max(m[i]);
            }
        }
        Node {
            lo,
            hi,
            start: start as u32,
            end: (start + entries.len()) as u32,
            least,
            first: 0,
        }
    }
}

/// Splits node `root` of `nodes` down to leaves of at most [`LEAF`] Gaussians, each at its
/// median along its box's longest axis, but for nodes of at most `piece` Gaussians, which it
/// returns unsplit. `entries` are the tree's order over `root`'s range.
fn split_down(
    entries: &mut [Entry],
    nodes: &mut Vec<Node>,
    root: usize,
    piece: usize,
) -> Vec<usize> {
    let offset = nodes[root].start as usize;
    let mut pieces = vec![];
    let mut split = vec![root];
    while let Some(i) = split.pop() {
        let Node { lo, hi, .. } = nodes[i];
        let (start, end) = (
            nodes[i].start as usize - offset,
            nodes[i].end as usize - offset,
        );
        if end - start <= LEAF {
            continue;
        }
        if end - start <= piece {
            pieces.push(i);
            continue;
        }
        let axis = (0..3).fold(0, |a, b| if hi[b] - lo[b] > hi[a] - lo[a] { b } else { a });
        // The median by the axis's coordinate. How Gaussians at one coordinate fall does
        // not matter: the search is exact whatever the tree's shape.
        let mid = start + (end - start) / 2;
        entries[start..end]
            .select_nth_unstable_by(mid - start, |(a, _), (b, _)| a[axis].total_cmp(&b[axis]));
        nodes[i].first = nodes.len() as u32;
        nodes.push(Node::over(&entries[start..mid], offset + start));
        nodes.push(Node::over(&entries[mid..end], offset + mid));
        split.extend([nodes.len() - 2, nodes.len() - 1]);
    }
    pieces
}
