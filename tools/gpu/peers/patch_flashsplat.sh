#!/usr/bin/env bash
# Copies FlashSplat's rasterizer source (florinshen/flashsplat-rasterization) to DST and
# makes it build with a modern toolchain (GCC 13+, nvcc 13, torch 2.11). Every change is
# valid on old toolchains too; the rasterizer's code is not otherwise touched.
#   - `#include <cstdint>` in the cuda_rasterizer headers and rasterize_points.cu:
#     rasterizer_impl.h uses uint32_t / std::uintptr_t without it, which GCC 13's
#     libstdc++ no longer pulls in transitively (the known diff-gaussian-rasterization
#     "'uint32_t' does not name a type" failure).
#   - rasterize_points.cu: AT_ERROR(msg) -> TORCH_CHECK(false, msg) (AT_ERROR is a
#     deprecated alias, dropped from newer torch headers), and the deprecated
#     Tensor::data<T>() -> Tensor::data_ptr<T>() (same pointer).
# Usage: patch_flashsplat.sh SRC DST   (SRC: a checkout with setup.py; DST: created)
set -euo pipefail
src=${1:?usage: patch_flashsplat.sh SRC DST}
dst=${2:?usage: patch_flashsplat.sh SRC DST}
if [ ! -f "$src/setup.py" ] || [ ! -f "$src/rasterize_points.cu" ]; then
  echo "$src is not a flashsplat-rasterization checkout" >&2; exit 1
fi
rm -rf "$dst"
mkdir -p "$dst"
cp -a "$src/." "$dst/"
rm -rf "$dst/build" "$dst"/*.egg-info
for f in "$dst"/cuda_rasterizer/*.h "$dst/rasterize_points.cu" "$dst/rasterize_points.h"; do
  grep -q '#include <cstdint>' "$f" || sed -i '1i #include <cstdint>' "$f"
done
sed -i -e 's/AT_ERROR(/TORCH_CHECK(false, /g' \
       -e 's/\.data<\([A-Za-z_:0-9]*\)>()/.data_ptr<\1>()/g' "$dst/rasterize_points.cu"
if grep -n 'AT_ERROR\|\.data<' "$dst/rasterize_points.cu"; then
  echo "patch_flashsplat.sh: leftovers above" >&2; exit 1
fi
echo "patched copy in $dst"
