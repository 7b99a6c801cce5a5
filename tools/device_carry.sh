#!/usr/bin/env bash
# Make here what a device call carries (tools/device_setup.sh unpacks it there): .gl/ (the GL loader .debs),
# .whl/ (cp312 wheels the device image lacks) and .carry/mi.tar.xz (Mitsuba's wheel without the variants,
# headers and plugins diviewer never loads: the whole wheel is 60 MiB, the call's limit 64 with the tree).
# All three are ignored (.git/info/exclude). Needs network here (pip, apt); run from anywhere.
# Then: run(command="bash tools/device_evalsets.sh ...", carry=[".gl", ".whl", ".carry"]).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
for d in /.gl/ /.whl/ /.carry/; do grep -qxF "$d" .git/info/exclude 2>/dev/null || echo "$d" >> .git/info/exclude; done
py=${PYTHON:-python3}
want() { "$py" -c "import importlib.metadata as m; print(m.version('$1'))"; }  # the versions this checkout runs
pkgs=(drjit moderngl glcontext trimesh OpenEXR flip-evaluator pyrr glfw)
specs=()
for p in "${pkgs[@]}"; do specs+=("$p==$(want "$p")"); done
mkdir -p .whl .carry .gl
plat=(--platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64
      --platform manylinux2014_x86_64 --platform manylinux1_x86_64)
"$py" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp "${plat[@]}" \
  -d .whl "${specs[@]}"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$py" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp "${plat[@]}" \
  -d "$tmp" "mitsuba==$(want mitsuba)"
(cd "$tmp" && unzip -q mitsuba-*.whl && rm mitsuba-*.whl)
m="$tmp/mitsuba"
rm -rf "$m/include" "$m/cmake" "$m/pkgconfig" "$m/data/sunsky"
for v in cuda_ad_mono cuda_ad_mono_polarized cuda_ad_spectral cuda_ad_spectral_polarized llvm_ad_mono \
         llvm_ad_mono_polarized llvm_ad_spectral llvm_ad_spectral_polarized scalar_mono scalar_mono_polarized \
         scalar_spectral scalar_spectral_polarized; do rm -f "$m/$v".cpython*.so; done
# Plugins diviewer's scenes never name (diviewer/reference/mitsuba.py: diffuse, twosided, mask, bitmap, area, point,
# directional, constant, volpath, aov, hdrfilm, perspective, box, rgb and what Mitsuba loads by default).
for p in bsplinecurve catmullrom ellipsoids ellipsoidsmesh sdfgrid sunsky timed_sunsky volpathmis linearcurve hair \
         measured measured_polarized polarizer retarder pplastic principled principledthin roughconductor \
         roughdielectric roughplastic plastic conductor dielectric thindielectric blendbsdf gridvolume heterogeneous \
         homogeneous sggx tabphase rayleigh hg blendphase ptracer stokes specfilm projector spot envmap \
         directionalarea thinlens orthographic irradiancemeter radiancemeter batch moment; do
  rm -f "$m/plugins/$p.so"
done
tar cf - -C "$tmp" mitsuba "$(cd "$tmp" && ls -d mitsuba-*.dist-info)" | xz -T0 -6 > .carry/mi.tar.xz.tmp
mv .carry/mi.tar.xz.tmp .carry/mi.tar.xz
mkdir -p "$tmp/apt/partial"
o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$tmp/apt")
apt-get "${o[@]}" update -qq
(cd .gl && apt-get "${o[@]}" download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
du -sh .gl .whl .carry
