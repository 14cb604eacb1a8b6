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

    pub fn pop(&mut self) -> Option<T> {
        let last = self.items.pop()?;
        if self.items.is_empty() {
            return Some(last);
        }
        let top = std::mem::replace(&mut self.items[0], last);
        let (mut at, len) = (0, self.items.len());
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
        Some(top)
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
}
