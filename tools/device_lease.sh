#!/usr/bin/env bash
# Set up a lent CUDA machine (the device tool) and start `diviewer build` there, detached.
#
# What travels with the call (ignored folders named in `carry`; see the README's "Models built on a GPU"):
#   .gl/     the GL loader .debs (libglvnd, libEGL, libGL, ...): apt-get download, as the device README says
#   .whl/    cp312 wheels the machine lacks: drjit moderngl glcontext trimesh OpenEXR flip-evaluator pyrr glfw
#   .carry/mi.tar.xz  Mitsuba 3.9.1's wheel unpacked without its spectral/mono variants and re-packed with xz
#            (the wheel is 60 MiB: with the tree it would not fit one call's 64 MiB)
# The build runs from a copy of the tree in /tmp/repo, so later calls' tree updates cannot touch it;
# its work folder is /tmp/dv (build.json, data/, evalset/, train_k*/, models/, ladder.json) and the chosen
# model is shipped into /tmp/dv/ship (SCENE.onnx, its card, curves, metrics, ladder); a lease is at most 30
# minutes, so give the build a --budget that fits (see docs/build.md), and run it again to resume.
#
# Usage on the device:  bash tools/device_lease.sh --scene sponza --budget 0.4    then poll /tmp/dv/build.log
set -euo pipefail
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
mkdir -p /tmp/site /tmp/dv
tar xJf .carry/mi.tar.xz -C /tmp/site
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site
nv=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
if [ -f "$nv" ]; then export __EGL_VENDOR_LIBRARY_FILENAMES=$nv; fi
rm -rf /tmp/repo && mkdir /tmp/repo && tar cf - --exclude=./.carry --exclude=./.whl --exclude=./.gl --exclude=./.git . | tar xf - -C /tmp/repo
cd /tmp/repo
python3 - <<'EOF'
import moderngl, mitsuba as mi
ctx = moderngl.create_context(standalone=True, backend="egl", require=430)
print("GL:", ctx.info["GL_RENDERER"], ctx.info["GL_VERSION"])
mi.set_variant("cuda_ad_rgb")
print("Mitsuba", mi.__version__, "variants", mi.variants())
from diviewer.reference.variant import select_variant
print("diviewer picks", select_variant())
EOF
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
setsid nohup python3 -m diviewer build --work /tmp/dv --ship /tmp/dv/ship "$@" > /tmp/dv/build.log 2>&1 < /dev/null &
echo "started diviewer build (pid $!): /tmp/dv/build.log"
