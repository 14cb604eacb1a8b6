//! A model of how a stretch of host work would scale to more cores than this machine has:
//! [`estimate_scaling`] times every item of the [`super::parallel_map`] calls the work makes
//! and schedules those items anew on 1, 2, 4, ... threads, as the pool hands them out (each
//! free thread takes the next index). The work between the calls counts as measured. A call
//! made inside an item (a wall's votes, counted in runs of its members) is modeled too, as
//! if it had every thread to itself: the item's time less the call's, plus the call's
//! items scheduled; calls deeper than that are part of their item's time.
//!
//! For deciding which passes would not scale on a GPU machine's sixteen cores while the
//! development machine has two: run the work on one core (`taskset -c 0`), so that each
//! item's time is its own and not shared with another thread's. What the model leaves
//! out: memory bandwidth and cache shared between the threads, the pool's own costs, a
//! machine's slower or faster cores, and work split by the number of cores (on one core,
//! such a pass is one item). An estimate, not a measurement.

use std::cell::{Cell, RefCell};
use std::panic::Location;
use std::time::Instant;

/// The thread counts [`Scaling`] gives times for.
pub const THREADS: [usize; 6] = [1, 2, 4, 8, 16, 32];

/// Seconds on each of [`THREADS`].
pub type PerThreads = [f64; THREADS.len()];

/// A stretch of work's wall time, measured, and modeled on each of [`THREADS`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scaling {
    pub measured_s: f64,
    /// Per entry of [`THREADS`]: the work between the calls as measured, each call's items
    /// scheduled on that many threads.
    pub modeled_s: PerThreads,
    /// Outermost parallel calls timed, and their wall time as measured.
    pub calls: usize,
    pub calls_s: f64,
    /// The same per place in the source that makes calls, in order of first call.
    pub by_place: Vec<PlaceScaling>,
}

/// The outermost calls made from one place in the source ([`Scaling::by_place`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlaceScaling {
    /// `file:line` of the call.
    pub place: String,
    pub calls: usize,
    pub calls_s: f64,
    /// Per entry of [`THREADS`], the calls' items scheduled on that many threads.
    pub scheduled_s: PerThreads,
    /// The longest item of any of the calls on 32 threads (what no number of threads
    /// takes under).
    pub longest_item_s: f64,
}

/// What the calls of the stretch being modeled add up to, per place.
#[derive(Default)]
struct Tally {
    by_place: Vec<PlaceScaling>,
}

/// Where a thread is: how deep in timed items, and for an outermost item, what the calls
/// made inside it change of its time on each of [`THREADS`].
#[derive(Clone, Copy, Default)]
struct InItem {
    depth: u8,
    nested_change_s: PerThreads,
}

thread_local! {
    /// The tally of the stretch this thread is modeling, if any.
    static TALLY: RefCell<Option<Tally>> = const { RefCell::new(None) };
    static IN_ITEM: Cell<InItem> = const { Cell::new(InItem { depth: 0, nested_change_s: [0.0; THREADS.len()] }) };
}

/// Runs `work` with the parallel calls it makes on this thread timed, and models it
/// ([`Scaling`]).
pub fn estimate_scaling<T>(work: impl FnOnce() -> T) -> (T, Scaling) {
    /// Puts back the tally of a stretch this one is inside, also where `work` panics.
    struct Restore(Option<Option<Tally>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            if let Some(outer) = self.0.take() {
                TALLY.with(|t| t.replace(outer));
            }
        }
    }
    let mut restore = Restore(Some(TALLY.with(|t| t.replace(Some(Tally::default())))));
    let start = Instant::now();
    let out = work();
    let measured_s = start.elapsed().as_secs_f64();
    let outer = restore.0.take().expect("restored once");
    let tally = TALLY.with(|t| t.replace(outer)).unwrap_or_default();
    let calls_s: f64 = tally.by_place.iter().map(|p| p.calls_s).sum();
    let between_s = (measured_s - calls_s).max(0.0);
    let scheduled = |t: usize| tally.by_place.iter().map(|p| p.scheduled_s[t]).sum::<f64>();
    let scaling = Scaling {
        measured_s,
        modeled_s: std::array::from_fn(|t| between_s + scheduled(t)),
        calls: tally.by_place.iter().map(|p| p.calls).sum(),
        calls_s,
        by_place: tally.by_place,
    };
    (out, scaling)
}

/// Whether a parallel call starting on this thread now is to be timed item by item, and if
/// so how deep its items are: 1 for an outermost call of a stretch being modeled, 2 for a
/// call inside one of its items (whichever thread runs that item).
pub(crate) fn timing_call() -> Option<u8> {
    match IN_ITEM.with(Cell::get).depth {
        0 => TALLY.with(|t| t.borrow().is_some()).then_some(1),
        1 => Some(2),
        _ => None,
    }
}

/// Runs one item of a timed call and returns its time on each of [`THREADS`]: as
/// measured, less what its own calls took, plus their items scheduled on that many.
pub(crate) fn timed_item(depth: u8, item: impl FnOnce()) -> PerThreads {
    /// Leaves the item, also where it panics (the pool's threads serve on).
    struct Leave(InItem);
    impl Drop for Leave {
        fn drop(&mut self) {
            IN_ITEM.with(|c| c.set(self.0));
        }
    }
    let outer = IN_ITEM.with(Cell::get);
    let _leave = Leave(outer);
    IN_ITEM.with(|c| {
        c.set(InItem {
            depth,
            nested_change_s: [0.0; THREADS.len()],
        })
    });
    let start = Instant::now();
    item();
    let measured_s = start.elapsed().as_secs_f64();
    let change = IN_ITEM.with(Cell::get).nested_change_s;
    std::array::from_fn(|t| (measured_s + change[t]).max(0.0))
}

/// Adds a timed call made on this thread from `place`: its wall time and its items' times
/// in index order. Inside an item, to that item's change; else to the stretch's tally.
pub(crate) fn add_call(place: &Location, wall_s: f64, items_s: &[PerThreads]) {
    let scheduled: PerThreads =
        std::array::from_fn(|t| schedule(items_s.iter().map(|item| item[t]), THREADS[t]));
    let mut in_item = IN_ITEM.with(Cell::get);
    if in_item.depth > 0 {
        for (change, s) in in_item.nested_change_s.iter_mut().zip(scheduled) {
            *change += s - wall_s;
        }
        IN_ITEM.with(|c| c.set(in_item));
        return;
    }
    let place = format!("{}:{}", place.file(), place.line());
    TALLY.with_borrow_mut(|tally| {
        let Some(tally) = tally.as_mut() else { return };
        let at = match tally.by_place.iter().position(|p| p.place == place) {
            Some(at) => at,
            None => {
                tally.by_place.push(PlaceScaling {
                    place,
                    ..Default::default()
                });
                tally.by_place.len() - 1
            }
        };
        let of_place = &mut tally.by_place[at];
        of_place.calls += 1;
        of_place.calls_s += wall_s;
        let last = THREADS.len() - 1;
        let longest = items_s.iter().map(|item| item[last]).fold(0.0, f64::max);
        of_place.longest_item_s = of_place.longest_item_s.max(longest);
        for (sum, s) in of_place.scheduled_s.iter_mut().zip(scheduled) {
            *sum += s;
        }
    });
}

/// When the last of `items_s` ends, each taken in index order by the first of `threads`
/// threads to be free.
pub fn schedule(items_s: impl IntoIterator<Item = f64>, threads: usize) -> f64 {
    let mut free_at = vec![0.0f64; threads.max(1)];
    for item in items_s {
        let first_free = (0..free_at.len())
            .min_by(|&a, &b| free_at[a].total_cmp(&free_at[b]))
            .expect("a thread");
        free_at[first_free] += item;
    }
    free_at.into_iter().fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Items go to the first free thread in index order: a long item last is not
    /// balanced away, one first is.
    #[test]
    fn schedule_takes_items_in_order() {
        assert_eq!(schedule([3.0, 1.0, 1.0, 1.0], 1), 6.0);
        assert_eq!(schedule([3.0, 1.0, 1.0, 1.0], 2), 3.0);
        assert_eq!(schedule([1.0, 1.0, 1.0, 3.0], 2), 4.0);
        assert_eq!(schedule([1.0, 1.0, 1.0, 3.0], 4), 3.0);
        assert_eq!(schedule([], 4), 0.0);
    }

    /// The outermost calls are tallied by place (a call inside an item changes that item's
    /// time), and two threads model no slower than one.
    #[test]
    fn only_outermost_calls_are_timed() {
        let (sums, scaling) = estimate_scaling(|| {
            super::super::parallel_map(6, |i| {
                super::super::parallel_map(3, |j| i * j)
                    .iter()
                    .sum::<usize>()
            })
        });
        assert_eq!(sums, vec![0, 3, 6, 9, 12, 15]);
        assert_eq!(scaling.calls, 1);
        assert_eq!(scaling.by_place.len(), 1);
        let place = &scaling.by_place[0].place;
        assert!(
            place.starts_with("src/util/scaling.rs:"),
            "the caller's place: {place}"
        );
        assert!(scaling.by_place[0].longest_item_s <= scaling.calls_s);
        assert!(scaling.calls_s <= scaling.measured_s);
        let [one, two, ..] = scaling.modeled_s;
        assert!(two <= one, "{scaling:?}");
        assert_eq!(timing_call(), None, "off after the stretch");
    }
}
