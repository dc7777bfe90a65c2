#!/usr/bin/env bash
# Session 20: the predictor tests on the GPU machine, set up as run.sh (the same carried files).
source .dev/c/setup.sh
python3 -c "import torch;print(torch.__version__, torch.cuda.get_device_name(0))"
python3 -m pytest -q -rs -p no:cacheprovider --durations=5 tests/test_predictor.py tests/test_predictor_text.py 2>&1 | tee $OUT/predictor-tests-gpu.log
