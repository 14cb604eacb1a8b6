//! Camera JSON (INRIA and semsplat) and class table parsing.
#![no_main]

use libfuzzer_sys::fuzz_target;
use semsplat::scene::cameras_json::parse_cameras_json;
use semsplat::scene::classes::ClassTable;

fuzz_target!(|data: &[u8]| {
    if let Ok((_, cams)) = parse_cameras_json(data) {
        assert!(!cams.is_empty());
        for c in &cams {
            c.validate().expect("parsed cameras are valid");
        }
    }
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(table) = ClassTable::from_json_str(text) {
            table.validate().expect("parsed tables are valid");
        }
    }
});
