//! A max-heap with four children per node, for large queues of small items.
//!
//! Why not `std::collections::BinaryHeap`: with millions of items a pop walks ~22 levels,
//! and below the cache each level is a miss; four children per node halve the levels and
//! fit a node's children in one or two cache lines. Segment consensus's clustering pops
//! millions of candidates (src/fuse/consensus_cluster.rs), where this halved the queue's time.

/// Max-heap: `pop` returns the greatest item (by `Ord`).
#[derive(Clone, Debug, Default)]
pub struct QuadHeap<T> {
    items: Vec<T>,
}

impl<T: Ord> QuadHeap<T> {
    pub fn new() -> QuadHeap<T> {
        QuadHeap { items: Vec::new() }
    }

    pub fn len(&self) -> usize {
        self.items.len()
    }

    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    pub fn peek(&self) -> Option<&T> {
        self.items.first()
    }

    pub fn push(&mut self, item: T) {
        self.items.push(item);
        let mut at = self.items.len() - 1;
        while at > 0 {
            let parent = (at - 1) / 4;
            if self.items[parent] >= self.items[at] {
                break;
            }
            self.items.swap(parent, at);
            at = parent;
        }
    }

    /// Keeps only the items `keep` accepts, and restores the heap order (bottom up, O(len)).
    pub fn retain(&mut self, keep: impl FnMut(&T) -> bool) {
        self.items.retain(keep);
        for at in (0..self.items.len().div_ceil(4)).rev() {
            self.sift_down(at);
        }
    }

    pub fn pop(&mut self) -> Option<T> {
        let last = self.items.pop()?;
        if self.items.is_empty() {
            return Some(last);
        }
        let top = std::mem::replace(&mut self.items[0], last);
        self.sift_down(0);
        Some(top)
    }

    /// Moves the item at `at` down until no child is greater.
    fn sift_down(&mut self, mut at: usize) {
        let len = self.items.len();
        loop {
            let first = 4 * at + 1;
            if first >= len {
                break;
            }
            let children = first..(first + 4).min(len);
            let best = children
                .reduce(|a, b| if self.items[b] > self.items[a] { b } else { a })
                .expect("at least one child");
            if self.items[best] <= self.items[at] {
                break;
            }
            self.items.swap(best, at);
            at = best;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    #[test]
    fn pops_in_the_order_a_sort_gives_with_pushes_between() {
        let mut rng = Rng::new(7);
        let (mut heap, mut reference) = (QuadHeap::new(), Vec::new());
        let mut popped = (Vec::new(), Vec::new());
        for round in 0..2000 {
            for _ in 0..(round % 5) {
                let x = (rng.next_u32() % 300, round);
                heap.push(x);
                reference.push(x);
            }
            if round % 3 != 0 {
                reference.sort();
                popped.0.push(heap.pop());
                popped.1.push(reference.pop());
            }
        }
        reference.sort();
        while let Some(x) = reference.pop() {
            popped.0.push(heap.pop());
            popped.1.push(Some(x));
        }
        assert_eq!(heap.pop(), None);
        assert!(popped.0.len() > 3000);
        assert_eq!(popped.0, popped.1);
    }

    #[test]
    fn retain_keeps_the_accepted_items_in_heap_order() {
        let mut rng = Rng::new(11);
        let mut heap = QuadHeap::new();
        let items: Vec<u32> = (0..5000).map(|_| rng.next_u32() % 1000).collect();
        for &x in &items {
            heap.push(x);
        }
        for _ in 0..700 {
            heap.pop();
        }
        heap.retain(|&x| x % 3 != 0);
        // What a sort of the survivors gives: the 700 greatest popped, then the multiples of
        // three dropped; pushes after the sweep go in order too.
        let mut expect: Vec<u32> = items.clone();
        expect.sort_unstable_by(|a, b| b.cmp(a));
        let mut expect: Vec<u32> = expect[700..]
            .iter()
            .copied()
            .filter(|x| x % 3 != 0)
            .collect();
        for x in [999, 0, 500] {
            heap.push(x);
            expect.push(x);
        }
        expect.sort_unstable_by(|a, b| b.cmp(a));
        let popped: Vec<u32> = std::iter::from_fn(|| heap.pop()).collect();
        assert!(popped.len() > 2500);
        assert_eq!(popped, expect);
    }
}
