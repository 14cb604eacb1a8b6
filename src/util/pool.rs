//! The worker threads [`super::parallel_map`] runs on: started once and kept for the
//! process, rather than spawned for each call.
//!
//! A segment consensus clusters and decides in about seventy parallel passes, most of them
//! milliseconds long. Spawned per call, each pass started a thread per core and ended them
//! again: every thread's stack mapped and unmapped (an unmap interrupts every core the
//! process runs on to flush its TLB, dear in a virtual machine of sixteen cores), and each
//! new thread's allocations met an empty cache of its own and went to the one malloc arena
//! (src/util/memory.rs). Kept threads pay that once.
//!
//! A call posts a job and works on it itself, as one of its threads; idle workers join
//! it. The caller never waits for a worker to *start*, only for those that joined to
//! finish, so a pass called from inside another's item (a worker waiting on a nested
//! call) still completes on its caller alone when every worker is busy: no deadlock.

use std::any::Any;
use std::collections::VecDeque;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, OnceLock};

/// A call's work as its helpers see it.
struct Job {
    /// The caller's work loop (it takes items until none is left), its lifetime erased.
    /// Valid while the caller waits in [`run_with_helpers`], which it does until no
    /// worker runs it, having first taken the job out of the queue so that none starts.
    work: *const (dyn Fn() + Sync + 'static),
    state: Mutex<JobState>,
    /// Signalled when the last running helper leaves.
    idle: Condvar,
}

// SAFETY: `work` points to a `Sync` closure that outlives every use of it (see `Job::work`).
unsafe impl Send for Job {}
// SAFETY: as above; the rest is behind a mutex.
unsafe impl Sync for Job {}

struct JobState {
    /// Workers still to join (the job leaves the queue at zero).
    wanted: usize,
    /// Workers running `work` now.
    running: usize,
    /// The first panic of a helper, raised again on the caller.
    panic: Option<Box<dyn Any + Send>>,
}

struct Pool {
    /// Jobs that want more helpers, oldest first.
    jobs: Mutex<VecDeque<Arc<Job>>>,
    posted: Condvar,
    workers: usize,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic in an item is caught before any lock is taken; nothing is left half-done.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The pool, started on first use with a worker for every core but the caller's.
fn pool() -> &'static Pool {
    static POOL: OnceLock<&'static Pool> = OnceLock::new();
    POOL.get_or_init(|| {
        let workers = super::cores().saturating_sub(1);
        let pool: &'static Pool = Box::leak(Box::new(Pool {
            jobs: Mutex::new(VecDeque::new()),
            posted: Condvar::new(),
            workers,
        }));
        for i in 0..workers {
            // A worker that cannot be started leaves its share to the others and the caller.
            let _ = std::thread::Builder::new()
                .name(format!("semsplat-worker-{i}"))
                .spawn(move || serve(pool));
        }
        pool
    })
}

/// A worker: joins the oldest job that wants help, runs its work loop, and waits for the next.
fn serve(pool: &'static Pool) {
    loop {
        let job = {
            let mut jobs = lock(&pool.jobs);
            loop {
                if let Some(job) = jobs.front().cloned() {
                    let mut state = lock(&job.state);
                    state.wanted -= 1;
                    state.running += 1;
                    if state.wanted == 0 {
                        jobs.pop_front();
                    }
                    drop(state);
                    break job;
                }
                jobs = pool.posted.wait(jobs).unwrap_or_else(|e| e.into_inner());
            }
        };
        // SAFETY: the caller waits until `running` is back to zero (see `Job::work`).
        let result = catch_unwind(AssertUnwindSafe(|| unsafe { (*job.work)() }));
        let mut state = lock(&job.state);
        if let Err(panic) = result {
            state.panic.get_or_insert(panic);
        }
        state.running -= 1;
        if state.running == 0 {
            job.idle.notify_all();
        }
    }
}

/// Runs `work` on the calling thread and on up to `helpers` idle workers at once, and
/// returns when every one of them has left it; a panic in any of them is raised here
/// after all have left.
pub(super) fn run_with_helpers(helpers: usize, work: &(dyn Fn() + Sync)) {
    let pool = pool();
    let helpers = helpers.min(pool.workers);
    if helpers == 0 {
        return work();
    }
    // SAFETY: only the lifetime is erased; this function does not return before the job
    // has left the queue and no worker runs `work` (the wait below).
    let erased: *const (dyn Fn() + Sync + 'static) =
        unsafe { std::mem::transmute(work as *const (dyn Fn() + Sync + '_)) };
    let job = Arc::new(Job {
        work: erased,
        state: Mutex::new(JobState {
            wanted: helpers,
            running: 0,
            panic: None,
        }),
        idle: Condvar::new(),
    });
    lock(&pool.jobs).push_back(Arc::clone(&job));
    for _ in 0..helpers {
        pool.posted.notify_one();
    }
    let mine = catch_unwind(AssertUnwindSafe(work));
    // No worker joins once the job is out of the queue (they join under its lock).
    lock(&pool.jobs).retain(|queued| !Arc::ptr_eq(queued, &job));
    let mut state = lock(&job.state);
    while state.running > 0 {
        state = job.idle.wait(state).unwrap_or_else(|e| e.into_inner());
    }
    let theirs = state.panic.take();
    drop(state);
    if let Err(panic) = mine {
        resume_unwind(panic);
    }
    if let Some(panic) = theirs {
        resume_unwind(panic);
    }
}

#[cfg(test)]
mod tests {
    use super::super::parallel_map;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// Maps inside maps, three deep, every level wider than the cores: each call completes
    /// (its caller works on it when every worker is busy) with every result in order.
    #[test]
    fn nested_maps_complete_in_order() {
        let out = parallel_map(9, |i| {
            parallel_map(7, |j| {
                parallel_map(5, |k| i * 100 + j * 10 + k)
                    .iter()
                    .sum::<usize>()
            })
        });
        for (i, row) in out.iter().enumerate() {
            let expected: Vec<usize> = (0..7)
                .map(|j| (0..5).map(|k| i * 100 + j * 10 + k).sum())
                .collect();
            assert_eq!(row, &expected);
        }
    }

    /// A panic in an item reaches the caller with its own message, only once no other item
    /// is running (the map's borrows end with the call), and the pool serves the next call.
    #[test]
    fn a_panicking_item_panics_the_caller_and_the_pool_serves_on() {
        let running = AtomicUsize::new(0);
        let caught = std::panic::catch_unwind(|| {
            parallel_map(64, |i| {
                running.fetch_add(1, Ordering::SeqCst);
                std::thread::sleep(std::time::Duration::from_micros(300));
                running.fetch_sub(1, Ordering::SeqCst);
                if i == 17 {
                    panic!("item 17 failed");
                }
            })
        });
        assert_eq!(
            running.load(Ordering::SeqCst),
            0,
            "an item outlived its map"
        );
        let message = caught.expect_err("the map panics");
        assert_eq!(message.downcast_ref::<&str>(), Some(&"item 17 failed"));
        let again = parallel_map(100, |i| i * 2);
        assert_eq!(again, (0..100).map(|i| i * 2).collect::<Vec<_>>());
    }

    /// A panic in a nested map's item (run on a worker or on a caller) passes up through
    /// both maps to the outer caller, with its message.
    #[test]
    fn a_nested_panic_reaches_the_outer_caller() {
        let caught = std::panic::catch_unwind(|| {
            parallel_map(8, |i| {
                parallel_map(8, |j| {
                    if (i, j) == (5, 6) {
                        panic!("item 5.6 failed");
                    }
                    i * j
                })
            })
        });
        let message = caught.expect_err("the maps panic");
        assert_eq!(message.downcast_ref::<&str>(), Some(&"item 5.6 failed"));
    }

    /// Several threads mapping at once share the workers: every map completes with its
    /// own results.
    #[test]
    fn concurrent_callers_each_get_their_results() {
        let outs: Vec<Vec<usize>> = std::thread::scope(|scope| {
            let calls: Vec<_> = (0..6)
                .map(|c| scope.spawn(move || parallel_map(500, |i| i * c)))
                .collect();
            calls.into_iter().map(|call| call.join().unwrap()).collect()
        });
        for (c, out) in outs.iter().enumerate() {
            assert_eq!(out, &(0..500).map(|i| i * c).collect::<Vec<_>>());
        }
    }
}
