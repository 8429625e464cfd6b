#!/usr/bin/env bash
# Run THERE, on a lent GPU machine, from the repository root (the device tool's working copy),
# after bench/gpu_prepare.sh here and with carry [".whl", ".gl", ".gpu-assets"] (and ".gpu-cache"
# after `gpu_prepare.sh --with-apartment`):
#   bash bench/gpu_device.sh [--parts fps mirrors walkthrough]
# Installs the carried wheels and GL loaders, checks that moderngl's EGL context is the GPU's
# (not llvmpipe), then runs python -m lobeview.bench.gpu at full size into $OUT (or
# bench/results without one). Under 8 minutes on one GPU is the plan: the parts run in order of
# what matters most, and each part that fails is reported without stopping the others.
set -uo pipefail
for deb in .gl/*.deb; do dpkg -x "$deb" /; done
ldconfig
# The NVIDIA EGL vendor file, where the image has it and nothing else was said (device README).
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
if [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ] && [ -f "$vendor" ]; then
    export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
fi
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
# The checkout is the package: reach it as `lobeview` from a folder beside it.
mkdir -p /tmp/lobeview-pkg && ln -sfn "$PWD" /tmp/lobeview-pkg/lobeview
export PYTHONPATH=/tmp/lobeview-pkg:/tmp/site PYTHONUNBUFFERED=1 LOBEVIEW_ASSETS="$PWD/.gpu-assets"
export LOBEVIEW_CACHE=/tmp/lobeview-cache
# Scenes baked here by bench/gpu_prepare.sh --with-apartment (found by their parameters' key).
mkdir -p "$LOBEVIEW_CACHE"
for packed in .gpu-cache/*.tar.xz; do
    [ -f "$packed" ] && tar -xJf "$packed" -C "$LOBEVIEW_CACHE"
done
out=${OUT:-bench/results}
python3 - <<'PY' || exit 1
from lobeview.viewer.context import create_headless_context, renderer_description
ctx = create_headless_context()
device = renderer_description(ctx)
print("device:", device, flush=True)
if "llvmpipe" in device.lower():
    raise SystemExit("EGL gave llvmpipe, not the GPU: check __EGL_VENDOR_LIBRARY_FILENAMES and the .gl packages")
PY
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv > "$out/gpu-nvidia-smi.csv" 2>&1 || true
python3 -m lobeview.bench.gpu --out "$out" "$@" 2>&1 | tee "$out/gpu-bench.log"
