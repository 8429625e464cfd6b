#!/usr/bin/env bash
# Run HERE (a machine with pip and apt-get), once per session that is lent a GPU machine: fetches
# what bench/gpu_device.sh needs there, where nothing can be downloaded (bench/README.md):
#   .whl/         lobeview's dependencies missing from the GPU image, as CPython 3.12 wheels
#   .gl/          the GL/EGL loader packages (libglvnd), unpacked there
#   .gpu-assets/  the HDR capture Table 4.1 uses ($LOBEVIEW_ASSETS there)
#   .gpu-cache/   with --with-apartment: the 12-room apartment baked here (~1-2 min on 2 cores),
#                 packed (~11 MB), so the walkthrough part there skips its 80 s bake (a lease is
#                 15 minutes; the third lease's walkthrough took 527 s with it)
# All are ignored by git (.git/info/exclude) and travel with `carry` (64 MiB in all, the checkout
# included: the apartment only fits packed).
set -euo pipefail
cd "$(dirname "$0")/.."
for folder in /.whl/ /.gl/ /.gpu-assets/ /.gpu-cache/; do
    grep -qxF "$folder" .git/info/exclude 2>/dev/null || echo "$folder" >> .git/info/exclude
done
rm -rf .whl && mkdir -p .whl
# Versions as pinned in pyproject.toml (and their own needs the GPU image lacks).
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 --platform manylinux1_x86_64 -d .whl \
    moderngl==5.13.0 glcontext==3.1.0 trimesh==4.12.2 embreex==4.4.0.post1 OpenEXR==3.4.17 \
    pygltflib==1.16.5 dataclasses-json==0.6.7 marshmallow==3.26.2 Deprecated==1.3.1 xatlas==0.0.11
rm -rf .gl && mkdir -p .gl /tmp/amd64/partial
apt_options=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64)
apt-get "${apt_options[@]}" update -qq
(cd .gl && apt-get "${apt_options[@]}" download libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
rm -rf .gpu-assets && mkdir -p .gpu-assets/env/blender_studiolights_1k
cp ../shared/assets/env/blender_studiolights_1k/interior.exr .gpu-assets/env/blender_studiolights_1k/
rm -rf .gpu-cache
if [ "${1:-}" = "--with-apartment" ]; then
    # The cache key is the scene's parameters, so what is baked here is found there.
    bake_cache=$(mktemp -d)
    "${PYTHON:-.venv/bin/python}" -c "
import sys
from lobeview.scenes.setup import load_scene_and_environment
load_scene_and_environment('builtin:apartment-12', None, sys.argv[1])
" "$bake_cache"
    mkdir -p .gpu-cache
    tar -cJf .gpu-cache/apartment-12.tar.xz -C "$bake_cache" apartment
    rm -rf "$bake_cache"
    carry='[".whl", ".gl", ".gpu-assets", ".gpu-cache"]'
else
    carry='[".whl", ".gl", ".gpu-assets"]'
fi
du -sh .whl .gl .gpu-assets .gpu-cache 2>/dev/null || true
echo "ready: run bench/gpu_device.sh through the device tool with carry $carry"
