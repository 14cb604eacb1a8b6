//! PLY reader: any bytes give Ok or Err (no panic, no huge allocation), and whatever reads
//! back writes and re-reads to the same scene.
#![no_main]

use libfuzzer_sys::fuzz_target;
use semsplat::scene::ply::{read_ply_from, write_ply_to};

fuzz_target!(|data: &[u8]| {
    // Stream of unknown length, then with the length known (the file path case).
    let streamed = read_ply_from(data, None);
    let sized = read_ply_from(data, Some(data.len() as u64));
    let Ok(g) = sized else { return };
    assert!(
        streamed.is_ok(),
        "the length hint must only reject what streaming rejects"
    );
    let _ = g.value_problems();
    let mut bytes = Vec::new();
    write_ply_to(&mut bytes, &g).expect("a scene we read must be writable");
    let again = read_ply_from(&bytes[..], Some(bytes.len() as u64)).expect("our own PLY must read");
    assert_eq!(format!("{g:?}"), format!("{again:?}"));
});
