//! A small bounding-volume hierarchy over primitive bounds, so a ray tests a handful of
//! primitives instead of all of them (living-room presets hold a few hundred parts).

use glam::DVec3;

use super::primitives::Aabb;

const LEAF_SIZE: usize = 2;
/// Median splits keep the depth near log2(n); 64 levels cover any realistic room.
const MAX_DEPTH: usize = 64;

#[derive(Clone, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first item in `items`; inner: index of the left child (the right one follows it).
    first: u32,
    /// Items in a leaf; 0 marks an inner node.
    count: u32,
}

#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    items: Vec<u32>,
}

impl Bvh {
    /// Builds over `bounds[i]` for items `i = 0..bounds.len()`.
    pub fn build(bounds: &[Aabb]) -> Bvh {
        let mut bvh = Bvh {
            nodes: Vec::new(),
            items: (0..bounds.len() as u32).collect(),
        };
        if !bounds.is_empty() {
            bvh.nodes.push(Node {
                bounds: Aabb::EMPTY,
                first: 0,
                count: 0,
            });
            bvh.split(0, 0, bounds.len(), bounds, 0);
        }
        bvh
    }

    fn split(&mut self, node: usize, start: usize, end: usize, bounds: &[Aabb], depth: usize) {
        let items = &mut self.items[start..end];
        let node_bounds = items
            .iter()
            .fold(Aabb::EMPTY, |acc, &i| acc.union(bounds[i as usize]));
        self.nodes[node].bounds = node_bounds;
        if items.len() <= LEAF_SIZE || depth + 1 >= MAX_DEPTH {
            self.nodes[node].first = start as u32;
            self.nodes[node].count = items.len() as u32;
            return;
        }
        let centers = items.iter().fold(Aabb::EMPTY, |acc, &i| {
            let c = bounds[i as usize].center();
            acc.union(Aabb { min: c, max: c })
        });
        let extent = centers.max - centers.min;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |&a, &b| {
            let (ca, cb) = (
                bounds[a as usize].center()[axis],
                bounds[b as usize].center()[axis],
            );
            ca.total_cmp(&cb).then(a.cmp(&b))
        });
        let left = self.nodes.len();
        self.nodes.push(Node {
            bounds: Aabb::EMPTY,
            first: 0,
            count: 0,
        });
        self.nodes.push(Node {
            bounds: Aabb::EMPTY,
            first: 0,
            count: 0,
        });
        self.nodes[node].first = left as u32;
        self.split(left, start, start + mid, bounds, depth + 1);
        self.split(left + 1, start + mid, end, bounds, depth + 1);
    }

    /// Calls `hit(item, t_max)` for every item whose bounds the ray may reach before `t_max`;
    /// `hit` returns the new, closer `t_max` when it found a nearer intersection.
    pub fn visit_ray(
        &self,
        origin: DVec3,
        dir: DVec3,
        mut t_max: f64,
        mut hit: impl FnMut(usize, f64) -> Option<f64>,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let inv_dir = dir.recip();
        // Entries carry the distance at which the ray enters the node, tested once.
        let mut stack = [(0u32, 0.0f64); MAX_DEPTH + 1];
        let Some(root_entry) = self.nodes[0].bounds.ray_entry(origin, inv_dir, t_max) else {
            return;
        };
        stack[0] = (0, root_entry);
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let (index, entry) = stack[len];
            if entry > t_max {
                continue;
            }
            let node = &self.nodes[index as usize];
            let first = node.first as usize;
            if node.count > 0 {
                for &item in &self.items[first..first + node.count as usize] {
                    if let Some(t) = hit(item as usize, t_max) {
                        t_max = t_max.min(t);
                    }
                }
                continue;
            }
            let left = self.nodes[first].bounds.ray_entry(origin, inv_dir, t_max);
            let right = self.nodes[first + 1]
                .bounds
                .ray_entry(origin, inv_dir, t_max);
            // Push the farther child first so the nearer one is visited first and prunes it.
            let mut children = [(first, left), (first + 1, right)];
            if left.unwrap_or(f64::INFINITY) < right.unwrap_or(f64::INFINITY) {
                children.swap(0, 1);
            }
            for (child, child_entry) in children {
                if let Some(e) = child_entry {
                    stack[len] = (child as u32, e);
                    len += 1;
                }
            }
        }
    }

    /// Candidate items for a point query: every item whose bounds (grown by `margin`) contain
    /// `p` is visited, and possibly a few neighbours sharing its leaf.
    pub fn visit_point(&self, p: DVec3, margin: f64, mut visit: impl FnMut(usize)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = [0u32; MAX_DEPTH + 1];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let node = &self.nodes[stack[len] as usize];
            if !node.bounds.contains(p, margin) {
                continue;
            }
            let first = node.first as usize;
            if node.count > 0 {
                self.items[first..first + node.count as usize]
                    .iter()
                    .for_each(|&i| visit(i as usize));
            } else {
                stack[len] = first as u32;
                stack[len + 1] = first as u32 + 1;
                len += 2;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box_at(x: f64) -> Aabb {
        Aabb {
            min: DVec3::new(x, 0.0, 0.0),
            max: DVec3::new(x + 0.5, 1.0, 1.0),
        }
    }

    #[test]
    fn ray_visits_every_box_it_crosses_and_point_queries_find_containers() {
        let bounds: Vec<Aabb> = (0..37).map(|i| unit_box_at(i as f64)).collect();
        let bvh = Bvh::build(&bounds);
        let mut seen = Vec::new();
        bvh.visit_ray(
            DVec3::new(-1.0, 0.5, 0.5),
            DVec3::X,
            f64::INFINITY,
            |i, _| {
                seen.push(i);
                None
            },
        );
        seen.sort();
        assert_eq!(seen, (0..37).collect::<Vec<_>>());
        let mut seen = Vec::new();
        bvh.visit_ray(
            DVec3::new(-1.0, 2.5, 0.5),
            DVec3::X,
            f64::INFINITY,
            |i, _| {
                seen.push(i);
                None
            },
        );
        assert!(seen.is_empty());
        let mut found = Vec::new();
        bvh.visit_point(DVec3::new(10.25, 0.5, 0.5), 0.0, |i| found.push(i));
        assert!(found.contains(&10) && found.len() <= 2, "{found:?}");
    }

    #[test]
    fn a_nearer_hit_prunes_farther_boxes() {
        let bounds: Vec<Aabb> = (0..64).map(|i| unit_box_at(i as f64)).collect();
        let bvh = Bvh::build(&bounds);
        let mut visited = 0;
        bvh.visit_ray(
            DVec3::new(-1.0, 0.5, 0.5),
            DVec3::X,
            f64::INFINITY,
            |i, _| {
                visited += 1;
                (i == 0).then_some(1.0)
            },
        );
        assert!(visited < 8, "visited {visited}");
    }
}
