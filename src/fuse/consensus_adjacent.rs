//! Segment consensus, the clustering's adjacency: per segment, its adjacent segments with the
//! evidence summed over the neighbour pairs between them.
//!
//! Why not a hash map for every segment: the clustering's joins are mostly lookups in the
//! adjacency of a segment met for the first time in a while (a neighbour's, to rename the
//! joined segment in it), so their time is cache misses. Most segments are a Gaussian or a
//! few, adjacent to about twice `k` others: a list of those, searched in order, is one or two
//! cache lines behind its header where a hash map's probe reads its control bytes and then
//! its slot, and grows by copying where a map rehashes. A segment adjacent to more than
//! [`LIST_MAX`] others (a wall) gets a hash map, where a list's search would read too much.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use super::consensus_cluster::PairEvidence;

/// The most adjacent segments kept in a list; past it, a hash map. 24 x 24 bytes: a search
/// reads at most 9 cache lines, in order.
pub const LIST_MAX: usize = 24;

type Map = HashMap<u32, PairEvidence, BuildHasherDefault<IdHasher>>;

/// A segment's adjacent segments (by segment id) with the summed evidence; iterated in no
/// particular order.
pub enum Adjacent {
    List(Vec<(u32, PairEvidence)>),
    Map(Map),
}

impl Default for Adjacent {
    fn default() -> Adjacent {
        Adjacent::List(Vec::new())
    }
}

impl Adjacent {
    /// Room for `n` adjacent segments (sized once: the graph's build knows every degree).
    pub fn with_capacity(n: usize) -> Adjacent {
        match n <= LIST_MAX {
            true => Adjacent::List(Vec::with_capacity(n)),
            false => Adjacent::Map(Map::with_capacity_and_hasher(n, Default::default())),
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Adjacent::List(list) => list.len(),
            Adjacent::Map(map) => map.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn get(&self, s: u32) -> Option<PairEvidence> {
        match self {
            Adjacent::List(list) => list.iter().find(|e| e.0 == s).map(|e| e.1),
            Adjacent::Map(map) => map.get(&s).copied(),
        }
    }

    pub fn remove(&mut self, s: u32) -> Option<PairEvidence> {
        match self {
            Adjacent::List(list) => {
                let at = list.iter().position(|e| e.0 == s)?;
                Some(list.swap_remove(at).1)
            }
            Adjacent::Map(map) => map.remove(&s),
        }
    }

    /// Adds `e` to the evidence with `s` (adjacent from now on if it was not) and returns
    /// the sum.
    pub fn add(&mut self, s: u32, e: PairEvidence) -> PairEvidence {
        if let Adjacent::List(list) = self {
            if let Some(entry) = list.iter_mut().find(|entry| entry.0 == s) {
                entry.1.add(e);
                return entry.1;
            }
            if list.len() < LIST_MAX {
                list.push((s, e));
                return e;
            }
            *self = Adjacent::Map(list.drain(..).collect());
        }
        let Adjacent::Map(map) = self else {
            unreachable!("a full list became a map above")
        };
        let sum = map.entry(s).or_default();
        sum.add(e);
        *sum
    }

    /// Segment `from` joined `to`: drops `from` and sets the evidence with `to` to `sum`
    /// (what the joined segment's evidence with this one is now). A list is searched once
    /// for both.
    pub fn rename(&mut self, from: u32, to: u32, sum: PairEvidence) {
        let list = match self {
            Adjacent::List(list) => list,
            Adjacent::Map(map) => {
                map.remove(&from);
                map.insert(to, sum);
                return;
            }
        };
        let (mut at_from, mut at_to) = (None, None);
        for (i, entry) in list.iter().enumerate() {
            if entry.0 == from {
                at_from = Some(i);
            } else if entry.0 == to {
                at_to = Some(i);
            }
        }
        match (at_from, at_to) {
            (Some(i), None) => list[i] = (to, sum),
            (from, Some(i)) => {
                list[i].1 = sum;
                if let Some(f) = from {
                    list.swap_remove(f);
                }
            }
            (None, None) => {
                self.add(to, sum);
            }
        }
    }

    /// Prefetches the first cache line of the list (a map: nothing).
    pub fn prefetch(&self) {
        if let Adjacent::List(list) = self {
            if let Some(first) = list.first() {
                crate::util::prefetch(first);
            }
        }
    }

    pub fn iter(&self) -> Iter<'_> {
        match self {
            Adjacent::List(list) => Iter::List(list.iter()),
            Adjacent::Map(map) => Iter::Map(map.iter()),
        }
    }
}

/// [`Adjacent::iter`]: (segment, evidence).
pub enum Iter<'a> {
    List(std::slice::Iter<'a, (u32, PairEvidence)>),
    Map(std::collections::hash_map::Iter<'a, u32, PairEvidence>),
}

impl Iterator for Iter<'_> {
    type Item = (u32, PairEvidence);

    fn next(&mut self) -> Option<(u32, PairEvidence)> {
        match self {
            Iter::List(list) => list.next().copied(),
            Iter::Map(map) => map.next().map(|(&s, &e)| (s, e)),
        }
    }
}

/// Keys are segment ids, so a multiplicative hash does (SipHash, the default, took most of
/// the graph's build time).
#[derive(Default)]
pub struct IdHasher(u64);

impl Hasher for IdHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }

    fn write_u32(&mut self, id: u32) {
        self.write_u64(id as u64);
    }

    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn evidence(x: u32) -> PairEvidence {
        PairEvidence {
            together: x,
            apart: x % 3,
            on_edge: x % 5,
            pairs: 1,
            pairs_along: 1,
        }
    }

    /// Against a plain HashMap, over random operations on ids from a small range (so
    /// entries meet again) through the list's growth into a map.
    #[test]
    fn adjacent_matches_a_hash_map() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = |m: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % m) as u32
        };
        for start in [0, 5, LIST_MAX + 3] {
            let mut adjacent = Adjacent::with_capacity(start);
            let mut model: HashMap<u32, PairEvidence> = HashMap::new();
            for _ in 0..4000 {
                let (s, t, e) = (next(40), next(40), evidence(next(9)));
                match next(4) {
                    0 => assert_eq!(adjacent.add(s, e), {
                        let sum = model.entry(s).or_default();
                        sum.add(e);
                        *sum
                    }),
                    1 => assert_eq!(adjacent.remove(s), model.remove(&s)),
                    2 if s != t => {
                        adjacent.rename(s, t, e);
                        model.remove(&s);
                        model.insert(t, e);
                    }
                    _ => assert_eq!(adjacent.get(s), model.get(&s).copied()),
                }
                assert_eq!(adjacent.len(), model.len());
            }
            let mut listed: Vec<_> = adjacent.iter().collect();
            let mut expected: Vec<_> = model.into_iter().collect();
            listed.sort_by_key(|e| e.0);
            expected.sort_by_key(|e| e.0);
            assert_eq!(listed, expected);
            assert!(matches!(adjacent, Adjacent::Map(_)), "grew past the list");
        }
    }
}
