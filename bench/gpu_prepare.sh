#!/usr/bin/env bash
# Run HERE (a machine with pip and apt-get), once per session that is lent a GPU machine: fetches
# what bench/gpu_device.sh needs there, where nothing can be downloaded (bench/README.md):
#   .whl/         lobeview's dependencies missing from the GPU image, as CPython 3.12 wheels
#   .gl/          the GL/EGL loader packages (libglvnd), unpacked there
#   .gpu-assets/  the HDR capture Table 4.1 uses ($LOBEVIEW_ASSETS there)
# All three are ignored by git (.git/info/exclude) and travel with `carry`.
set -euo pipefail
cd "$(dirname "$0")/.."
for folder in /.whl/ /.gl/ /.gpu-assets/; do
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
du -sh .whl .gl .gpu-assets
echo "ready: run bench/gpu_device.sh through the device tool with carry [.whl, .gl, .gpu-assets]"
