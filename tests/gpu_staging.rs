//! Reused staging buffers (src/gpu/staging.rs): uploads and downloads recorded into the
//! caller's submission land where they should, across transfers that grow the buffers, with
//! the synchronization validation silent.

mod common;

use semsplat::gpu::{Recorder, Staging};

#[test]
fn staged_transfers_round_trip_and_grow() {
    let gpu = common::gpu();
    let (a, b) = (
        gpu.buffer("a", 4096).unwrap(),
        gpu.buffer("b", 4096).unwrap(),
    );
    let mut staging = Staging::default();
    // Small, then larger transfers (the buffers grow), then small again (reused).
    for (round, (len_a, len_b)) in [(3usize, 5usize), (700, 1000), (1, 2)]
        .into_iter()
        .enumerate()
    {
        let data_a = common::random_u32(len_a, 10 + round as u64);
        let data_b = common::random_u32(len_b, 20 + round as u64);
        let mut rec = Recorder::new(gpu).unwrap();
        staging
            .record_uploads(gpu, &mut rec, &[(&a, &data_a[..]), (&b, &data_b[..])])
            .unwrap();
        // A kernel-free use between upload and download: b's first word overwritten, which
        // the download must see (the barriers order the copies around it).
        rec.fill(&b, 0, 4, 7);
        rec.barrier();
        let ranges = [(&a, 4 * len_a as u64), (&b, 4 * len_b as u64)];
        staging.record_downloads(gpu, &mut rec, &ranges).unwrap();
        rec.submit_and_wait().unwrap();
        let read = staging.read::<u32>();
        let mut expect_b = data_b.clone();
        expect_b[0] = 7;
        assert_eq!(read, vec![data_a, expect_b], "round {round}");
    }
    common::check_validation(gpu);
}

#[test]
fn staged_download_of_nothing_reads_empty() {
    let gpu = common::gpu();
    let a = gpu.buffer("a", 64).unwrap();
    let mut staging = Staging::default();
    let mut rec = Recorder::new(gpu).unwrap();
    staging.record_uploads::<u32>(gpu, &mut rec, &[]).unwrap();
    staging.record_downloads(gpu, &mut rec, &[(&a, 0)]).unwrap();
    rec.submit_and_wait().unwrap();
    assert_eq!(staging.read::<u32>(), vec![Vec::<u32>::new()]);
    common::check_validation(gpu);
}
