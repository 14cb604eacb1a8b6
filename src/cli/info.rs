//! `semsplat info`: the Vulkan devices, which one semsplat picks, and what it supports.

use anyhow::Result;
use clap::Args;
use serde::Serialize;

use semsplat::gpu::caps::device_type_name;
use semsplat::gpu::context::{choose_device, DeviceCandidate};
use semsplat::gpu::{list_devices, DeviceCaps, GpuError};

#[derive(Args)]
pub struct InfoArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct DeviceReport<'a> {
    index: usize,
    selected: bool,
    missing_features: &'a [String],
    #[serde(flatten)]
    caps: &'a DeviceCaps,
}

fn gib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 30) as f64
}

pub fn run(args: InfoArgs) -> Result<()> {
    let devices = list_devices()?;
    let wanted = std::env::var("SEMSPLAT_DEVICE").ok();
    let selected = choose_device(&devices, wanted.as_deref());
    let selected_index = selected.as_ref().ok().copied();
    if args.json {
        let reports: Vec<_> = devices
            .iter()
            .map(|d| DeviceReport {
                index: d.index,
                selected: Some(d.index) == selected_index,
                missing_features: &d.missing,
                caps: &d.caps,
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&reports)?);
    } else {
        for d in &devices {
            print_device(d, Some(d.index) == selected_index);
        }
    }
    match selected {
        Ok(_) => Ok(()),
        Err(
            e @ (GpuError::NoDevice
            | GpuError::NoSuitableDevice(_)
            | GpuError::DeviceNotFound { .. }),
        ) => Err(e.into()),
        Err(e) => Err(e.into()),
    }
}

/// One device's capabilities, as `info` prints them.
fn print_device(d: &DeviceCandidate, selected: bool) {
    let c = &d.caps;
    let mark = if selected { " (selected)" } else { "" };
    println!("[{}] {}{mark}", d.index, c.name);
    println!("    type:              {}", device_type_name(c.device_type));
    println!(
        "    driver:            {} ({})",
        c.driver_name, c.driver_info
    );
    println!("    Vulkan:            {}", c.vulkan_version);
    println!(
        "    subgroup size:     {} (range {}..={})",
        c.subgroup_size, c.min_subgroup_size, c.max_subgroup_size
    );
    println!("    float32 atomic add: {}", yes_no(c.float_atomic_add));
    // Without it the projection runs in float32 (README, "Limits"): worth a line.
    println!(
        "    float64:           {}",
        match c.float64 {
            true => "yes (projection in float64)",
            false => "no (projection in float32)",
        }
    );
    println!(
        "    int64 / atomics:   {} / {}",
        yes_no(c.int64),
        yes_no(c.int64_atomics)
    );
    println!(
        "    timestamps:        {}{}",
        yes_no(c.timestamps),
        if c.timestamps {
            format!(" ({} ns per tick)", c.timestamp_period_ns)
        } else {
            String::new()
        }
    );
    println!(
        "    max storage binding: {:.0} MiB",
        c.max_storage_buffer_range as f64 / (1u64 << 20) as f64
    );
    if let Some(cap) = c.loop_iteration_cap {
        println!(
            "    loop cap:          {cap} iterations per invocation (lists walked in windows)"
        );
    }
    for (i, h) in c.heaps.iter().enumerate() {
        let local = if h.device_local {
            "device-local"
        } else {
            "host"
        };
        println!(
            "    heap {i}:            {:.2} GiB {local}",
            gib(h.size_bytes)
        );
    }
    if !d.missing.is_empty() {
        println!("    NOT USABLE, lacks: {}", d.missing.join(", "));
    }
}

fn yes_no(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "no"
    }
}
