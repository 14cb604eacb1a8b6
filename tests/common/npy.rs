//! `.npy` files built as numpy writes them, for the readers' tests.

/// A version 1.0 `.npy` file: magic, the header dict `dict` padded with spaces to a
/// multiple of 64 bytes and ended by '\n', then `raw` (the little-endian values).
pub fn npy_v1(dict: &str, raw: &[u8]) -> Vec<u8> {
    let mut header = dict.to_string();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(raw);
    out
}
