//! The allocator's setup (`configure_malloc`, which the CLI calls first): threads taking
//! turns allocating and freeing blocks of megabytes, as the label readers do with their
//! maps, get their memory back from the heap rather than faulting it in anew each time.
//! glibc only: elsewhere `configure_malloc` sets nothing.
#![cfg(all(target_os = "linux", target_env = "gnu"))]

use std::sync::Barrier;

/// Minor page faults of this process so far.
fn faults() -> i64 {
    // SAFETY: getrusage only writes the struct it is given.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    usage.ru_minflt
}

/// Two threads, in lockstep: the first allocates a map, the second one above it, then
/// the first frees its map and the second its own, leaving two maps free at the heap's
/// top. glibc's moving thresholds give that back to the system at every round (its trim
/// threshold settles at twice a map), so each round faulted both maps in again.
#[test]
fn maps_freed_in_turns_are_reused_not_faulted_again() {
    semsplat::util::memory::configure_malloc();
    const MAP: usize = 8 << 20;
    const ROUNDS: usize = 24;
    let barrier = Barrier::new(2);
    let round = |first: bool| {
        let mut held = None;
        for step in 0..4 {
            if step == usize::from(!first) {
                held = Some(std::hint::black_box(vec![1u8; MAP]));
            }
            if step == 2 + usize::from(!first) {
                held = None;
            }
            barrier.wait();
        }
        drop(held);
    };
    let mut counted = Vec::new();
    std::thread::scope(|scope| {
        scope.spawn(|| (0..ROUNDS).for_each(|_| round(false)));
        for _ in 0..ROUNDS {
            let before = faults();
            round(true);
            counted.push(faults() - before);
        }
    });
    // The first rounds grow the heap; after them a round should fault next to nothing
    // (a map is 2,048 pages: each round faulted about 4,096 with the moving thresholds).
    let later: i64 = counted[4..].iter().sum();
    let pages = (MAP / 4096) as i64;
    assert!(
        later < pages,
        "{later} faults over {} later rounds ({counted:?})",
        ROUNDS - 4
    );
}
