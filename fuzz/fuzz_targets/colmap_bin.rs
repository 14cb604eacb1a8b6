//! COLMAP binary readers: the first two bytes split the input into cameras.bin and images.bin.
#![no_main]

use libfuzzer_sys::fuzz_target;
use semsplat::scene::colmap::{colmap_to_cameras, read_cameras_bin_from, read_images_bin_from};

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let split = (u16::from_le_bytes([data[0], data[1]]) as usize).min(data.len() - 2);
    let (cams, images) = data[2..].split_at(split);
    let cams = read_cameras_bin_from(&mut &cams[..]);
    let images = read_images_bin_from(&mut &images[..]);
    if let (Ok(cams), Ok(images)) = (cams, images) {
        let _ = colmap_to_cameras(&cams, &images);
    }
});
