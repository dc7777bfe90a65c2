"""Which part of the tiny training differs between two CUDA runs: the embeddings or the training?"""
import os, sys, tempfile
from pathlib import Path
import numpy as np
import torch
sys.path.insert(0, os.getcwd())
from tests.test_predictor import TinyWorld, _train_tiny
from predictor.embed import Embedder
from predictor.features import event_text

w = TinyWorld()
texts = [event_text(ev) for ev in w.events]
tmp = Path(tempfile.mkdtemp())
a = Embedder(None, tmp / "a", device="cuda").embed(texts)
Embedder(None, tmp / "b", device="cuda").embed(texts[::-2])
b = Embedder(None, tmp / "b", device="cuda").embed(texts)
print("embeddings: texts", len(texts), "bitwise equal rows", int((a == b).all(1).sum()), "max abs diff", float(np.abs(a - b).max()))
c = Embedder(None, tmp / "c", device="cuda").embed(texts)
print("embeddings, same batches again: equal rows", int((a == c).all(1).sum()))

def weights(d):
    return {f.name: f.read_bytes() for f in d.iterdir() if f.suffix in (".pt", ".npy")}

m1 = weights(_train_tiny(w, tmp / "m1", tmp / "a"))
m2 = weights(_train_tiny(w, tmp / "m2", tmp / "a"))
print("same cache, two trainings: equal files", {k: m1[k] == m2[k] for k in m1})
m3 = weights(_train_tiny(w, tmp / "m3", tmp / "b"))
print("cache b: equal files", {k: m1[k] == m3[k] for k in m1})
os.environ["CUBLAS_WORKSPACE_CONFIG"] = ":4096:8"
torch.use_deterministic_algorithms(True)
try:
    d1 = weights(_train_tiny(w, tmp / "d1", tmp / "a"))
    d2 = weights(_train_tiny(w, tmp / "d2", tmp / "a"))
    print("deterministic algorithms, two trainings: equal files", {k: d1[k] == d2[k] for k in d1})
except Exception as e:  # noqa: BLE001
    print("deterministic algorithms refused:", str(e).splitlines()[0])
