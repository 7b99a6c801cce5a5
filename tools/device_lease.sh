#!/usr/bin/env bash
# Set up a lent CUDA machine (tools/device_setup.sh) and start `diviewer build` there, detached.
#
# Its work folder is /tmp/dv (build.json, data/, evalset/, train_k*/, models/, ladder.json) and the chosen
# model is shipped into /tmp/dv/ship (SCENE.onnx, its card, curves, metrics, ladder); a lease is at most 30
# minutes, so give the build a --budget that fits (see docs/build.md), and run it again to resume.
# tools/device_ladder.py is the other way to use a lease: a recipe's capture and K ladder against a deadline.
#
# Usage on the device:  bash tools/device_lease.sh --scene sponza --budget 0.4    then poll /tmp/dv/build.log
. tools/device_setup.sh
setsid nohup python3 -m diviewer build --work /tmp/dv --ship /tmp/dv/ship "$@" > /tmp/dv/build.log 2>&1 < /dev/null &
echo "started diviewer build (pid $!): /tmp/dv/build.log"
