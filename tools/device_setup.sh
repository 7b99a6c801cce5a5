# Set up a lent CUDA machine (the device tool) for diviewer: source it (`. tools/device_setup.sh`) from the
# repository root; it leaves PYTHONPATH and the NVIDIA EGL vendor exported and a copy of the tree in /tmp/repo
# (later calls' tree updates cannot touch a job started there), and cds into it.
#
# What travels with the call (ignored folders named in `carry`; see docs/build.md, "Accelerators"; `bash
# tools/device_carry.sh` makes all three here):
#   .gl/     the GL loader .debs (libglvnd, libEGL, libGL, ...): apt-get download, as the device README says
#   .whl/    cp312 wheels the machine lacks: drjit moderngl glcontext trimesh OpenEXR flip-evaluator pyrr glfw
#   .carry/mi.tar.xz  Mitsuba 3.9.1's wheel unpacked without its spectral/mono variants, headers and the
#            plugins diviewer never loads, re-packed with xz (the wheel is 60 MiB: with the tree it would not fit one
#            call's 64 MiB)
set -euo pipefail
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
mkdir -p /tmp/site /tmp/dv
tar xJf .carry/mi.tar.xz -C /tmp/site
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1
nv=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
if [ -f "$nv" ]; then export __EGL_VENDOR_LIBRARY_FILENAMES=$nv; fi
rm -rf /tmp/repo && mkdir /tmp/repo && tar cf - --exclude=./.carry --exclude=./.whl --exclude=./.gl --exclude=./.git . | tar xf - -C /tmp/repo
cd /tmp/repo
python3 - <<'PY'
import moderngl, mitsuba as mi
ctx = moderngl.create_context(standalone=True, backend="egl", require=430)
print("GL:", ctx.info["GL_RENDERER"], ctx.info["GL_VERSION"])
mi.set_variant("cuda_ad_rgb")
print("Mitsuba", mi.__version__, "variants", mi.variants())
from diviewer.reference.variant import select_variant
print("diviewer picks", select_variant())
PY
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
