//! A parallel map over indices on every core, for CPU work whose items differ in cost
//! (threads take the next index as they finish, so slow items do not stall a fixed split),
//! and the sorted-list helpers the parallel passes share (merging runs, searching near).

use std::ops::Range;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

use super::pool::run_with_helpers;

/// The cores this process may run on (1 where the system does not say).
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `f(0), ..., f(count - 1)`, computed on up to all cores, in index order: on the calling
/// thread and the process's kept worker threads (src/util/pool.rs).
#[track_caller]
pub fn parallel_map<T: Send>(count: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    match super::scaling::timing_call() {
        Some(depth) => timed_parallel_map(std::panic::Location::caller(), depth, count, f),
        None => on_pool(count, f),
    }
}

/// `f(0), ..., f(count - 1)` on the calling thread and the pool's workers, in index order.
fn on_pool<T: Send>(count: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let items = Items::new(count);
    let helpers = cores().min(count).saturating_sub(1);
    run_with_helpers(helpers, &|| items.compute(&f));
    items.into_results()
}

/// [`parallel_map`], each item timed for [`super::scaling::estimate_scaling`].
fn timed_parallel_map<T: Send>(
    place: &std::panic::Location,
    depth: u8,
    count: usize,
    f: impl Fn(usize) -> T + Sync,
) -> Vec<T> {
    let start = std::time::Instant::now();
    let timed = on_pool(count, |i| {
        let mut value = None;
        let seconds = super::scaling::timed_item(depth, || value = Some(f(i)));
        (value.expect("computed"), seconds)
    });
    let wall_s = start.elapsed().as_secs_f64();
    let (results, items_s): (Vec<T>, Vec<_>) = timed.into_iter().unzip();
    super::scaling::add_call(place, wall_s, &items_s);
    results
}

/// `f(0), ..., f(count - 1)` computed on every core in blocks of `block` indices (each
/// block one work item: a lock per index would cost more than most items), in index order.
/// Each block is written in place into the one list ([`collect_parts`]): a list per block
/// was an allocation on the worker threads, which share one malloc arena
/// (src/util/memory.rs), and the segment clustering's rounds make thousands of calls.
#[track_caller]
pub fn map_in_blocks<T: Send>(count: usize, block: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let block = block.max(1);
    let range = |b: usize| b * block..count.min((b + 1) * block);
    let lens = (0..count.div_ceil(block)).map(|b| range(b).len()).collect();
    collect_parts(lens, |b| range(b).map(&f))
}

/// [`parallel_map`] on at most `threads` threads, started for the call and ended after
/// it: for items that each hold much memory while they are computed (a large label map
/// decoded), so that their number bounds how many run at once, and whatever a thread keeps
/// for its next item (the decoder's buffer of samples) goes with the call.
pub fn parallel_map_on<T: Send>(
    threads: usize,
    count: usize,
    f: impl Fn(usize) -> T + Sync,
) -> Vec<T> {
    let items = Items::new(count);
    let threads = cores().min(threads).min(count).max(1);
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| items.compute(&f));
        }
    });
    items.into_results()
}

/// The items of a parallel map: each thread takes the next index as it finishes one, so
/// slow items do not stall a fixed split.
struct Items<T> {
    results: Mutex<Vec<Option<T>>>,
    next: AtomicUsize,
    count: usize,
}

impl<T> Items<T> {
    fn new(count: usize) -> Items<T> {
        Items {
            results: Mutex::new((0..count).map(|_| None).collect()),
            next: AtomicUsize::new(0),
            count,
        }
    }

    /// Computes items until none is left to take.
    fn compute(&self, f: &impl Fn(usize) -> T) {
        loop {
            let i = self.next.fetch_add(1, Ordering::Relaxed);
            if i >= self.count {
                return;
            }
            let value = f(i);
            self.results.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(value);
        }
    }

    fn into_results(self) -> Vec<T> {
        (self.results.into_inner().unwrap_or_else(|e| e.into_inner()))
            .into_iter()
            .map(|v| v.expect("every index was computed"))
            .collect()
    }
}

/// Seconds spent in a closure, summed over the threads that ran it (a worker pool's busy
/// time, beside the wall time its consumer waited).
#[derive(Default)]
pub struct BusyTime(AtomicU64);

impl BusyTime {
    /// Runs `f`, adding its time.
    pub fn time<T>(&self, f: impl FnOnce() -> T) -> T {
        let start = std::time::Instant::now();
        let out = f();
        self.0
            .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        out
    }

    pub fn seconds(&self) -> f64 {
        self.0.load(Ordering::Relaxed) as f64 * 1e-9
    }
}

/// Items of `weights` cut into consecutive runs of about `target` total weight, as index
/// ranges: each run closes at the item that brings it to `target` or past it (an item
/// heavier than `target`: a run of its own, or the end of one). Work items for
/// [`parallel_map`] where items weigh very differently (a segment of a wall against
/// thousands of a few Gaussians): by count, the heavy ones would meet in a few items.
pub fn runs_of_weight(
    weights: impl IntoIterator<Item = usize>,
    target: usize,
) -> Vec<Range<usize>> {
    let (mut runs, mut start, mut held, mut count) = (Vec::new(), 0, 0, 0);
    for (i, weight) in weights.into_iter().enumerate() {
        held += weight;
        count = i + 1;
        if held >= target {
            runs.push(start..i + 1);
            (start, held) = (i + 1, 0);
        }
    }
    if start < count {
        runs.push(start..count);
    }
    runs
}

/// `data` cut into consecutive parts of `lens` (summing to at most its length), each behind
/// a lock: the disjoint outputs of a [`parallel_map`] whose index `i` fills part `i` (each
/// lock taken once, never waited on). Filled so, a parallel pass allocates nothing on its
/// worker threads.
pub fn split_parts<T>(
    mut data: &mut [T],
    lens: impl IntoIterator<Item = usize>,
) -> Vec<Mutex<&mut [T]>> {
    let mut parts = Vec::new();
    for len in lens {
        let (part, rest) = std::mem::take(&mut data).split_at_mut(len);
        parts.push(Mutex::new(part));
        data = rest;
    }
    parts
}

/// The items of parts `0..counts.len()` in one list, in order, each part written in place on
/// its thread (`part(i)` yields exactly `counts[i]` items: counted first, by a cheaper pass
/// than the one that makes them). Where each part's list copied into one would write all of
/// it again on one thread (a million Gaussians' neighbour pairs: 110 MB, each page faulted
/// in anew), and allocate on the workers under one malloc arena.
#[track_caller]
pub fn collect_parts<T: Send, I: Iterator<Item = T>>(
    counts: Vec<usize>,
    part: impl Fn(usize) -> I + Sync,
) -> Vec<T> {
    let (parts_count, total) = (counts.len(), counts.iter().sum());
    let mut items: Vec<T> = Vec::with_capacity(total);
    let parts = split_parts(&mut items.spare_capacity_mut()[..total], counts);
    parallel_map(parts_count, |i| {
        let mut slots = take_part(&parts[i]);
        let mut slots = slots.iter_mut();
        for item in part(i) {
            slots
                .next()
                .expect("no more items than counted")
                .write(item);
        }
        assert!(slots.next().is_none(), "as many items as counted");
    });
    drop(parts);
    // SAFETY: the parts cover the first `total` slots and each part's thread wrote every
    // slot of its part (both asserted there; a panic there stops us in parallel_map).
    unsafe { items.set_len(total) };
    items
}

/// Part `part` of [`split_parts`], locked (a panic on another thread does not poison it).
pub fn take_part<'p, 'd, T>(part: &'p Mutex<&'d mut [T]>) -> MutexGuard<'p, &'d mut [T]> {
    part.lock().unwrap_or_else(|e| e.into_inner())
}

/// Runs `produce(0), ..., produce(count - 1)` on up to `threads` worker threads, at most
/// `ahead` items ahead of the consumer, and hands the results to `consume` on the calling
/// thread in index order. The consumer's work (e.g. GPU submissions) overlaps the
/// production of the next items (e.g. decoding label maps). The first error, from either
/// side, stops both and is returned.
pub fn prefetch_ordered<T: Send>(
    count: usize,
    threads: usize,
    ahead: usize,
    produce: impl Fn(usize) -> anyhow::Result<T> + Sync,
    mut consume: impl FnMut(usize, T) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    use std::collections::BTreeMap;
    use std::sync::Condvar;
    struct State<T> {
        ready: BTreeMap<usize, anyhow::Result<T>>,
        consumed: usize,
        stop: bool,
    }
    let ahead = ahead.max(1);
    let state = Mutex::new(State {
        ready: BTreeMap::new(),
        consumed: 0,
        stop: false,
    });
    let changed = Condvar::new();
    let next = AtomicUsize::new(0);
    let lock = || state.lock().unwrap_or_else(|e| e.into_inner());
    let wait = |g| changed.wait(g).unwrap_or_else(|e| e.into_inner());
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, count.max(1)) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= count {
                    return;
                }
                let mut g = lock();
                // Wait for room: at most `ahead` items past the consumer.
                while !g.stop && i >= g.consumed + ahead {
                    g = wait(g);
                }
                if g.stop {
                    return;
                }
                drop(g);
                let item = produce(i);
                lock().ready.insert(i, item);
                changed.notify_all();
            });
        }
        let result = (0..count).try_for_each(|i| {
            let mut g = lock();
            let item = loop {
                if let Some(item) = g.ready.remove(&i) {
                    break item;
                }
                g = wait(g);
            };
            g.consumed = i + 1;
            drop(g);
            changed.notify_all();
            consume(i, item?)
        });
        lock().stop = true;
        changed.notify_all();
        result
    })
}

/// Sorted runs merged into one sorted list, pairs of runs merged on every core, round by
/// round (the last merge, of two halves, on one): runs sorted on every core and merged so
/// sort millions of items (the ordered joins' first candidates, the Gaussians by grid
/// cell) where one sort ran on one core.
pub fn merge_sorted_runs<T: Ord + Copy + Send + Sync>(mut runs: Vec<Vec<T>>) -> Vec<T> {
    while runs.len() > 1 {
        let pairs = runs.len().div_ceil(2);
        let merged = parallel_map(pairs, |i| match runs.get(2 * i + 1) {
            Some(second) => merge_two(&runs[2 * i], second),
            None => runs[2 * i].clone(),
        });
        runs = merged;
    }
    runs.pop().unwrap_or_default()
}

/// Two sorted lists merged (equal items: the first list's first).
fn merge_two<T: Ord + Copy>(first: &[T], second: &[T]) -> Vec<T> {
    let mut out = Vec::with_capacity(first.len() + second.len());
    out.extend_from_slice(first);
    merge_sorted_into(&mut out, second);
    out
}

/// Merges the sorted `fresh` into the sorted `into`, from the back, in place (equal items:
/// `into`'s first).
pub fn merge_sorted_into<T: Ord + Copy>(into: &mut Vec<T>, fresh: &[T]) {
    let (mut i, mut j) = (into.len(), fresh.len());
    // The new slots are all written below; `fresh` only fills them first.
    into.extend_from_slice(fresh);
    while j > 0 {
        let at = i + j - 1;
        if i > 0 && into[i - 1] > fresh[j - 1] {
            into[at] = into[i - 1];
            i -= 1;
        } else {
            into[at] = fresh[j - 1];
            j -= 1;
        }
    }
}

/// The partition point of `items` under `below` (true on a prefix, false after), found by
/// steps doubling from the start and then a binary search of the last step: its cost grows
/// with the log of the answer, not of the length. For a sorted list searched in order for
/// ascending keys, each search starting where the last ended (a segment's views looked up
/// in a larger segment's: the answers are near).
pub fn partition_point_near<T>(items: &[T], below: impl Fn(&T) -> bool) -> usize {
    let (mut passed, mut step) = (0, 1);
    while passed + step <= items.len() && below(&items[passed + step - 1]) {
        passed += step;
        step *= 2;
    }
    // Every item before `passed` is below; the one at `passed + step - 1` (if any) is not.
    let end = (passed + step - 1).min(items.len());
    passed + items[passed..end].partition_point(below)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parts of any count, empty ones among them, give their items in one list in part
    /// order; a part that yields fewer items than counted stops the call.
    #[test]
    fn collect_parts_lists_every_part_in_order() {
        let counts = vec![3, 0, 5, 1, 0, 700];
        let items = |i: usize| (0..counts[i]).map(move |j| (i, j));
        let expected: Vec<(usize, usize)> = (0..counts.len()).flat_map(items).collect();
        assert_eq!(collect_parts(counts.clone(), items), expected);
        let short = std::panic::catch_unwind(|| collect_parts(vec![2, 2], |i| 0..i + 1));
        assert!(short.is_err(), "part 0 yields 1 of 2");
    }

    /// Runs keep the items in order, each but the last reaching the target, none past it
    /// by more than its last item.
    #[test]
    fn runs_of_weight_cover_the_items_in_order() {
        let mut rng = crate::util::Rng::new(3);
        let items: Vec<usize> = (0..2000).map(|_| 1 + rng.below(3000) as usize).collect();
        for target in [1, 500, 4096, 1 << 30] {
            let ranges = runs_of_weight(items.iter().copied(), target);
            let runs: Vec<&[usize]> = ranges.into_iter().map(|r| &items[r]).collect();
            assert_eq!(runs.concat(), items, "target {target}");
            for (r, run) in runs.iter().enumerate() {
                let held: usize = run.iter().sum();
                let before_last = held - run.last().unwrap();
                assert!(before_last < target, "target {target}, run {r}");
                let last = r + 1 == runs.len();
                assert!(last || held >= target, "target {target}, run {r}");
            }
        }
        assert!(runs_of_weight([], 10).is_empty());
    }

    /// Blocks of any size, the last one short, give the items of one map in order.
    #[test]
    fn map_in_blocks_is_a_map_in_order() {
        for (count, block) in [(0, 4), (1, 4), (10, 3), (12, 4), (1000, 7), (5, 0)] {
            let expected: Vec<String> = (0..count).map(|i| format!("{}", i * i)).collect();
            let got = map_in_blocks(count, block, |i| format!("{}", i * i));
            assert_eq!(got, expected, "{count} in blocks of {block}");
        }
    }

    /// Runs of every length (none, one, odd counts of runs, empty runs among them) merge
    /// to what one sort of all their items gives.
    #[test]
    fn sorted_runs_merge_to_one_sort() {
        let mut rng = crate::util::Rng::new(5);
        for count in [0, 1, 2, 3, 7, 16] {
            let mut runs: Vec<Vec<u32>> = (0..count)
                .map(|r| {
                    let len = if r % 3 == 1 {
                        0
                    } else {
                        rng.below(500) as usize
                    };
                    let mut run: Vec<u32> = (0..len).map(|_| rng.below(300) as u32).collect();
                    run.sort_unstable();
                    run
                })
                .collect();
            let mut expected = runs.concat();
            expected.sort_unstable();
            runs.rotate_left(count / 2);
            assert_eq!(merge_sorted_runs(runs), expected, "{count} runs");
        }
    }

    /// The doubling search finds what a binary search of the whole list finds, for every
    /// key of sorted lists of every short length and some long ones, duplicates included.
    #[test]
    fn partition_point_near_is_the_partition_point() {
        let mut rng = crate::util::Rng::new(11);
        for len in (0..40).chain([100, 1000, 4097]) {
            let mut items: Vec<u32> = (0..len).map(|_| rng.below(60) as u32).collect();
            items.sort_unstable();
            for key in 0..62 {
                let expected = items.partition_point(|&x| x < key);
                assert_eq!(
                    partition_point_near(&items, |&x| x < key),
                    expected,
                    "{len} {key}"
                );
            }
        }
    }

    /// Each index fills its own part: the parts cover the data in order, of the lengths asked.
    #[test]
    fn split_parts_hand_each_index_its_own_part() {
        let mut data = vec![0usize; 10];
        let lens = [3, 0, 4, 2];
        let parts = split_parts(&mut data, lens);
        parallel_map(lens.len(), |i| {
            let mut part = take_part(&parts[i]);
            assert_eq!(part.len(), lens[i]);
            part.iter_mut().for_each(|x| *x = i + 1);
        });
        drop(parts);
        assert_eq!(data, [1, 1, 1, 3, 3, 3, 3, 4, 4, 0]);
    }

    /// At most `threads` items are computed at once, whatever the cores, and every result
    /// comes back in index order.
    #[test]
    fn parallel_map_on_runs_at_most_its_threads_at_once() {
        // The results of `parallel_map_on(threads, count, i -> 3i)` and the most items that
        // ran at once.
        let run = |threads: usize, count: usize| {
            let (running, most) = (AtomicUsize::new(0), AtomicUsize::new(0));
            let out = parallel_map_on(threads, count, |i| {
                let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                most.fetch_max(now, Ordering::SeqCst);
                std::thread::sleep(std::time::Duration::from_millis(2));
                running.fetch_sub(1, Ordering::SeqCst);
                i * 3
            });
            (out, most.load(Ordering::SeqCst))
        };
        let (out, most) = run(2, 24);
        assert_eq!(out, (0..24).map(|i| i * 3).collect::<Vec<_>>());
        assert!(most <= 2);
        assert_eq!(run(1, 8).1, 1);
    }
}
