//! The process's own memory use, for reports.

/// Peak resident memory of this process in bytes (Linux `VmHWM`); None where the kernel
/// does not report it.
pub fn peak_host_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    #[test]
    fn peak_grows_with_a_touched_allocation() {
        let before = super::peak_host_bytes().unwrap();
        let block = vec![1u8; 64 << 20];
        let after = super::peak_host_bytes().unwrap();
        assert!(block.iter().all(|&b| b == 1));
        assert!(after >= before + (60 << 20), "{before} -> {after}");
    }
}
