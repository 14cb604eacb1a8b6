#!/usr/bin/env bash
# Installs what semsplat needs on a fresh Debian (bookworm) machine, then builds the merged
# shaderc archive that .cargo/config.toml points shaderc-sys at. Idempotent; run as root
# (or with sudo available). Recipe and reasons: docs/TOOLCHAIN.md.
set -euo pipefail

say() { printf '[setup] %s\n' "$*"; }
die() { printf '[setup] ERROR: %s\n' "$*" >&2; exit 1; }

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || die "run as root, or install sudo"
  SUDO=sudo
fi

# Vulkan loader + lavapipe (CPU Vulkan driver) + validation layers, and shaderc's pieces.
packages=(
  libvulkan1 libvulkan-dev mesa-vulkan-drivers vulkan-tools vulkan-validationlayers
  libshaderc-dev glslang-dev spirv-tools binutils
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  say "installing: ${missing[*]}"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${missing[@]}"
else
  say "system packages already installed"
fi

# Debian's libshaderc.so expects glslang statically and its libshaderc_combined.a lacks
# glslang: merge the static archives into one that links on its own.
arch_dir=/usr/lib/$(gcc -dumpmachine 2>/dev/null || echo x86_64-linux-gnu)
[ -d "$arch_dir" ] || arch_dir=/usr/lib/x86_64-linux-gnu
out="$repo/.toolchain/shaderc"
lib="$out/libshaderc_combined.a"
parts=(libshaderc_combined.a libglslang.a libMachineIndependent.a libGenericCodeGen.a
       libOSDependent.a libOGLCompiler.a libSPIRV.a libHLSL.a
       libglslang-default-resource-limits.a libSPIRV-Tools-opt.a libSPIRV-Tools.a)
if [ -s "$lib" ] && [ "$lib" -nt "$arch_dir/libglslang.a" ]; then
  say "merged shaderc archive up to date: $lib"
else
  mkdir -p "$out"
  script="CREATE $lib.tmp"$'\n'
  for a in "${parts[@]}"; do
    [ -f "$arch_dir/$a" ] || die "missing $arch_dir/$a (is glslang-dev / libshaderc-dev installed?)"
    script+="ADDLIB $arch_dir/$a"$'\n'
  done
  script+=$'SAVE\nEND\n'
  say "merging ${#parts[@]} static archives into $lib"
  rm -f "$lib.tmp"
  printf '%s' "$script" | ar -M || die "ar -M failed"
  mv "$lib.tmp" "$lib"
fi

# Confirm the loader sees a device (lavapipe at least).
if command -v vulkaninfo >/dev/null; then
  dev=$(vulkaninfo --summary 2>/dev/null | grep -m1 deviceName | sed 's/.*= //') || true
  [ -n "${dev:-}" ] || die "the Vulkan loader finds no device (try VK_LOADER_DEBUG=error vulkaninfo)"
  say "Vulkan device: $dev"
fi
# Ray, for the sharded-fusion driver (tools/ray/fuse_sharded.py) and its test (tests/ray_shards.rs).
if python3 -c 'import ray' 2>/dev/null; then
  say "ray already installed: $(python3 -c 'import ray; print(ray.__version__)')"
else
  command -v python3 >/dev/null || die "python3 not found (needed for ray)"
  if ! python3 -m pip --version >/dev/null 2>&1; then
    say "installing pip (python3-pip)"
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q python3-pip
  fi
  say "installing ray (pip)"
  # Debian's own python3 refuses system-wide pip installs (PEP 668) unless told otherwise.
  python3 -m pip install -q 'ray>=2.58' \
    || python3 -m pip install -q --break-system-packages 'ray>=2.58' \
    || die "pip install ray failed (see tools/ray/README.md)"
fi
command -v cargo >/dev/null || die "cargo not found: install Rust (rustup) first"
say "done"
