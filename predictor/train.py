"""Training of the demand networks, with early stopping and a checkpoint after every epoch (torch).

Paper settings (defaults): MSE loss, Adam with lr 1e-4 and weight decay 1e-6,
batch 64, batches reshuffled every epoch, 100 epochs.  surge treats the 100
epochs as a cap: each network keeps the weights of the epoch with the lowest
loss on the validation months (July–August) and stops ``patience`` (10)
epochs after it.  The standard network trains on every (hour, sector) of
January–June; the event-sector networks on the (hour, sector) samples of
those months where the sector has an active event (the only inputs they will
ever see).

Resume: ``<out>/checkpoints/<net>.pt`` holds the weights, the optimiser state
and the loss history after the last finished epoch.  A run that finds a
checkpoint with the same configuration and data signature continues from the
next epoch (with the best weights and the early-stopping state); the shuffle
of epoch ``e`` is drawn from a generator seeded with ``(seed, e)``, so an
interrupted and resumed run ends with the same weights as an uninterrupted
one.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from torch import nn

from city.logs import steps
from predictor.nets import DemandMLP, build, configure_threads

logger = logging.getLogger(__name__)


@dataclass
class TrainConfig:
    """Training settings.  ``epochs`` is the cap; training stops earlier on validation loss.

    ``patience``: stop after this many epochs without a new best validation
    loss (the weights of the best epoch are kept); 0 trains every epoch of the
    cap and still keeps the best epoch's weights.  ``device``: ``cpu``,
    ``cuda`` or ``auto`` (CUDA where present).  ``eval_batch`` is the batch of
    the validation pass (no gradients, so large batches are cheap).
    """

    epochs: int = 100
    lr: float = 1e-4
    weight_decay: float = 1e-6
    batch_size: int = 64
    seed: int = 0
    patience: int = 10
    device: str = "cpu"
    eval_batch: int = 8192

    def to_json(self) -> dict:
        return dict(epochs=self.epochs, lr=self.lr, weight_decay=self.weight_decay, batch_size=self.batch_size, seed=self.seed, patience=self.patience, device=self.device, eval_batch=self.eval_batch)


def resolve_device(device: str) -> torch.device:
    """``auto`` → CUDA where available, else CPU; ``cuda`` without a GPU is refused with one line."""
    from city.errors import ConfigError

    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device == "cuda" and not torch.cuda.is_available():
        raise ConfigError("--device cuda: no CUDA device is available (use --device auto or cpu)")
    if device not in ("cpu", "cuda"):
        raise ConfigError(f"--device {device!r}: choose from auto, cpu, cuda")
    return torch.device(device)


@dataclass
class FitResult:
    net: DemandMLP
    losses: list[float] = field(default_factory=list)
    val_losses: list[float] = field(default_factory=list)
    epoch_seconds: list[float] = field(default_factory=list)
    resumed_from: int = 0
    best_epoch: int = 0  # 1-based epoch whose weights were kept (0: none trained)
    stopped_early: bool = False
    device: str = "cpu"

    def to_json(self) -> dict:
        return {
            "epochs_run": len(self.losses),
            "best_epoch": self.best_epoch,
            "stopped_early": self.stopped_early,
            "losses": self.losses,
            "val_losses": self.val_losses,
            "device": self.device,
        }


def _signature(name: str, X: np.ndarray, y: np.ndarray, hidden: tuple[int, ...], cfg: TrainConfig, y_val: np.ndarray | None) -> str:
    h = hashlib.sha256()
    h.update(json.dumps([name, list(X.shape), list(hidden), cfg.lr, cfg.weight_decay, cfg.batch_size, cfg.seed, cfg.patience]).encode())
    h.update(np.ascontiguousarray(y).tobytes())
    h.update(np.ascontiguousarray(X[:: max(1, len(X) // 997)]).tobytes())
    if y_val is not None:
        h.update(np.ascontiguousarray(y_val).tobytes())
    return h.hexdigest()[:20]


def _atomic_save(obj, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def _cpu_state(net: nn.Module) -> dict:
    return {k: v.detach().to("cpu", copy=True) for k, v in net.state_dict().items()}


def _mse(net: nn.Module, X: torch.Tensor, y: torch.Tensor, batch: int) -> float:
    net.eval()
    total = torch.zeros((), dtype=torch.float64, device=X.device)
    with torch.no_grad():
        for i in range(0, X.shape[0], batch):
            d = net(X[i : i + batch]) - y[i : i + batch]
            total += (d.double() ** 2).sum()
    return float(total) / max(1, X.shape[0])


def fit(
    name: str,
    X: np.ndarray,
    y: np.ndarray,
    hidden: tuple[int, ...],
    cfg: TrainConfig,
    *,
    X_val: np.ndarray | None = None,
    y_val: np.ndarray | None = None,
    checkpoint: Path | None = None,
    log: Callable[[str], None] | None = print,
) -> FitResult:
    """Train one network on ``(X, y)``, stopping early on the loss of ``(X_val, y_val)``; resumable.

    Without validation data every epoch of the cap runs and the last weights
    are kept.  With it, the weights of the epoch with the lowest validation
    loss are kept, and training stops ``cfg.patience`` epochs after it.
    """
    configure_threads()
    device = resolve_device(cfg.device)
    # Tensors go to the device once; batches are gathered there by index.
    X_t = torch.from_numpy(np.ascontiguousarray(X, dtype=np.float32)).to(device)
    y_t = torch.from_numpy(np.ascontiguousarray(y, dtype=np.float32)).to(device)
    has_val = X_val is not None and y_val is not None and len(y_val) > 0
    if has_val:
        Xv_t = torch.from_numpy(np.ascontiguousarray(X_val, dtype=np.float32)).to(device)
        yv_t = torch.from_numpy(np.ascontiguousarray(y_val, dtype=np.float32)).to(device)
    n = X_t.shape[0]
    net = build(X_t.shape[1], hidden, cfg.seed).to(device)
    # The fused kernel updates all parameters in one pass: on 2 cores it cuts the
    # 2 x 4096 network's optimiser step from ~10x to ~1/3 of a forward pass.
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, fused=True)
    loss_fn = nn.MSELoss()
    sig = _signature(name, X, y, hidden, cfg, y_val if has_val else None)
    result = FitResult(net=net, device=str(device))
    start = 0
    best_state: dict | None = None
    best_val = float("inf")
    if checkpoint is not None and checkpoint.exists():
        try:
            ck = torch.load(checkpoint, map_location="cpu", weights_only=False)
        except Exception as exc:  # a corrupt checkpoint: start over, say so
            ck = None
            if log:
                log(f"[{name}] ignoring unreadable checkpoint {checkpoint} ({exc})")
        if ck is not None and ck.get("signature") == sig:
            net.load_state_dict(ck["model"])
            opt.load_state_dict(ck["optim"])
            start = int(ck["epoch"])
            result.losses = list(ck["losses"])
            result.val_losses = list(ck.get("val_losses", []))
            result.epoch_seconds = list(ck["epoch_seconds"])
            result.best_epoch = int(ck.get("best_epoch", 0))
            result.stopped_early = bool(ck.get("stopped_early", False))
            best_state = ck.get("best_state")
            best_val = float(ck.get("best_val", float("inf")))
            result.resumed_from = start
            if log:
                log(f"[{name}] resuming after epoch {start}/{cfg.epochs} from {checkpoint}")
        elif ck is not None and log:
            log(f"[{name}] checkpoint {checkpoint} is for other data or settings; starting over")
    if n == 0:
        if log:
            log(f"[{name}] no training samples; network left untrained")
        return result
    bs = cfg.batch_size
    t_total = sum(result.epoch_seconds)
    epoch = start
    bar = steps(cfg.epochs - start, "epoch", f"train {name}")
    while epoch < cfg.epochs and not result.stopped_early:
        t0 = time.perf_counter()
        g = torch.Generator().manual_seed(cfg.seed * 1_000_003 + epoch)
        perm = torch.randperm(n, generator=g).to(device)
        net.train()
        total = torch.zeros((), dtype=torch.float64, device=device)
        for i in range(0, n, bs):
            idx = perm[i : i + bs]
            xb, yb = X_t[idx], y_t[idx]
            opt.zero_grad(set_to_none=True)
            loss = loss_fn(net(xb), yb)
            loss.backward()
            opt.step()
            total += loss.detach().double() * len(idx)  # no host sync per batch
        train_loss = float(total) / n
        result.losses.append(train_loss)
        msg = ""
        if has_val:
            v = _mse(net, Xv_t, yv_t, cfg.eval_batch)
            result.val_losses.append(v)
            if v < best_val:
                best_val, best_state, result.best_epoch = v, _cpu_state(net), epoch + 1
            elif cfg.patience > 0 and epoch + 1 - result.best_epoch >= cfg.patience:
                result.stopped_early = True
            msg = f"  val_loss {v:.5f}  best {best_val:.5f} @ {result.best_epoch}"
        else:
            result.best_epoch = epoch + 1
        dt_s = time.perf_counter() - t0
        t_total += dt_s
        result.epoch_seconds.append(dt_s)
        epoch += 1
        if checkpoint is not None:
            _atomic_save(
                {
                    "signature": sig,
                    "model": _cpu_state(net),
                    "optim": opt.state_dict(),
                    "epoch": epoch,
                    "losses": result.losses,
                    "val_losses": result.val_losses,
                    "epoch_seconds": result.epoch_seconds,
                    "best_epoch": result.best_epoch,
                    "best_val": best_val,
                    "best_state": best_state,
                    "stopped_early": result.stopped_early,
                },
                checkpoint,
            )
        if log:
            stop = "  (early stop)" if result.stopped_early else ""
            log(f"[{name}] epoch {epoch:3d}/{cfg.epochs}  train_loss {train_loss:.5f}{msg}  {dt_s:6.1f}s  (total {t_total:7.1f}s){stop}")
        bar.update()
    bar.close()
    net = net.to("cpu")
    if has_val and best_state is not None:
        net.load_state_dict(best_state)
    net.eval()
    result.net = net
    return result


def predict(net: nn.Module, X: np.ndarray, batch: int = 8192) -> np.ndarray:
    configure_threads()
    net.eval()
    dev = next(net.parameters()).device
    out = []
    with torch.no_grad():
        for i in range(0, len(X), batch):
            out.append(net(torch.from_numpy(np.ascontiguousarray(X[i : i + batch], dtype=np.float32)).to(dev)).cpu().numpy())
    return np.concatenate(out) if out else np.zeros(0, np.float32)


def versions() -> dict:
    import platform

    from city.fingerprint import machine

    # The host too: the same command on another processor can give other weights.
    out = {"python": platform.python_version(), "torch": torch.__version__, "numpy": np.__version__,
           "machine": machine(), "cpu_capability": torch.backends.cpu.get_cpu_capability()}
    for mod in ("scipy", "sklearn", "sentence_transformers", "transformers"):
        try:
            out[mod] = __import__(mod).__version__
        except Exception:
            pass
    try:
        from predictor import __version__

        out["surge.predictor"] = __version__
    except Exception:
        pass
    return out


def log_line(msg: str) -> None:
    """Training's progress and what it read, at INFO."""
    logger.info("%s", msg)
