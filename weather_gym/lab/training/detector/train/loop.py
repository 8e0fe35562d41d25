"""The training loop: :func:`train_detector` (seeded, checkpointed every epoch, resumable) and its loss
(:func:`detection_loss`: focal loss on the heatmaps, L1 on sizes and offsets).

Example:
    >>> _device("cpu").type
    'cpu'
"""

from __future__ import annotations

import io
import json
import math
import os
import pickle
import platform
import time
import zipfile
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from weather_gym.core._io import atomic_write, check_output, exclusive
from weather_gym.core.errors import FileFormatError, InputError
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.training.detector.conenet import NUM_CLASSES, ConeNet, ConeNetExport
from weather_gym.lab.training.detector.train.config import TrainConfig
from weather_gym.lab.training.detector.train.data import _EpochBatches, _Frames, _one_thread, _stack
from weather_gym.lab.training.detector.train.export import export_onnx, load_onnx_weights
from weather_gym.perception.onnx_detector import Detections
from weather_gym.perception.preprocess import decode, letterbox
from weather_gym.perception.scoring import evaluate


# ----------------------------------------------------------------------------------- loss
def detection_loss(raw: torch.Tensor, heat, ign, ind, size, off, mask, hreg=None, hmask=None
                   ) -> tuple[torch.Tensor, dict[str, float]]:
    """Penalty-reduced focal loss on the heatmaps (ignored cells carry no negative loss) + L1 on
    log-size and offset at object centres. A hidden-cone net (raw ``2C+4`` channels, heat ``2C``) gets
    the same focal loss on its hidden-cone heatmaps, reported as ``hidden``; one with hidden-cone boxes
    (raw ``2C+8``) an L1 on their log size and offset in the cells of ``hmask`` (``hreg`` the targets of
    ``build_targets(..., hidden_boxes=True)``), averaged over those cells, reported as ``hidden_box``."""
    c = NUM_CLASSES
    n = mask.sum().clamp(min=1.0)

    def focal_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        pred = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
        pos = target.eq(1.0).float()
        neg_w = torch.pow(1 - target, 4) * (1 - (ign[:, None] if ign.dim() == 3 else ign)) * (1 - pos)
        pos_loss = (torch.log(pred) * torch.pow(1 - pred, 2) * pos).sum()
        neg_loss = (torch.log(1 - pred) * torch.pow(pred, 2) * neg_w).sum()
        return -(pos_loss + neg_loss) / n

    focal = focal_loss(raw[:, :c], heat[:, :c])
    extra: dict[str, float] = {}
    if raw.shape[1] in (2 * c + 4, 2 * c + 8):
        if heat.shape[1] != 2 * c:
            raise InputError(f"a hidden-cone net needs {2 * c} heat targets, got {heat.shape[1]}")
        hidden = focal_loss(raw[:, c + 4 : 2 * c + 4], heat[:, c:])
        focal = focal + hidden
        extra["hidden"] = hidden.item()
    if raw.shape[1] == 2 * c + 8:
        if hreg is None or hmask is None:
            raise InputError("a net with hidden-cone boxes needs their targets (build_targets(..., hidden_boxes=True))")
        hm = hmask[:, None]
        hidden_box = (torch.abs(raw[:, 2 * c + 4 :] - hreg) * hm).sum() / hmask.sum().clamp(min=1.0)
        extra["hidden_box"] = hidden_box.item()
    else:
        hidden_box = 0.0
    b, _, h, w = raw.shape
    flat = raw[:, c : c + 4].reshape(b, 4, h * w)
    g = torch.gather(flat, 2, ind[:, None, :].expand(b, 4, ind.shape[1]))  # (B, 4, M)
    m = mask[:, None, :]
    size_l = (torch.abs(g[:, :2] - size.transpose(1, 2)) * m).sum() / n
    off_l = (torch.abs(torch.sigmoid(g[:, 2:]) - off.transpose(1, 2)) * m).sum() / n
    total = focal + size_l + off_l + hidden_box
    return total, {"focal": focal.item(), "size": size_l.item(), "offset": off_l.item(), **extra}


def _device(name: str) -> torch.device:
    """``TrainConfig.device`` as a torch device; a clear error where CUDA is asked for and absent."""
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"device {name!r}: this torch ({torch.__version__}) sees no CUDA GPU; use --device cpu")
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise InputError(f"device {name!r}: only {torch.cuda.device_count()} CUDA GPU(s) are visible")
    return device


def _hardware(cfg: TrainConfig, device: torch.device) -> str:
    """Where the net was trained, for the sidecar."""
    cpu = f"{platform.processor() or platform.machine()}, {cfg.threads} torch threads, {cfg.workers} sample workers"
    if device.type == "cuda":
        return f"{torch.cuda.get_device_name(device)} (CUDA); {cpu}"
    return f"{cpu}, CPU"


def _freeze_bn(net: ConeNet) -> None:
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.eval()


# ----------------------------------------------------------------------------------- training
def _eval_map(net: ConeNet, val, cfg: TrainConfig, max_images: int = 200) -> float:
    """mAP@0.5 of the torch model on (up to ``max_images`` frames of) ``val``, via the runtime decoder."""

    model = ConeNetExport(net).eval()
    n = min(len(val), max_images)
    dets, gts = [], []
    with torch.no_grad():
        for start in range(0, n, 16):
            idx = range(start, min(n, start + 16))
            ims = [val.image(i) for i in idx]
            boxed = [letterbox(im, cfg.input_size) for im in ims]
            x = torch.from_numpy(np.stack([b[0].transpose(2, 0, 1) for b in boxed])).float()
            out = model(x.to(next(net.parameters()).device)).cpu().numpy()
            for (boxes, scores, classes), (_, lb) in zip(decode(out, NUM_CLASSES, net.stride, 0.05), boxed, strict=True):
                dets.append(Detections(lb.to_original(boxes).astype(np.float32), scores, classes))
            gts += [val.gt(i) for i in idx]
    return evaluate(gts, dets).map50


def _same_run(ckpt: Path, state: dict, cfg: TrainConfig, data: list) -> None:
    """Refuse to resume ``ckpt`` with other settings or data (InputError naming what differs)."""
    before: dict[str, Any] = state.get("config") if isinstance(state.get("config"), dict) else {}  # type: ignore[assignment]  # a dict: checked
    now = asdict(cfg)
    diff = [k for k in now if before.get(k) != now[k]] + [k for k in before if k not in now]
    if state.get("data") != [str(d) for d in data]:
        diff.append("data")
    if diff:
        shown = "; ".join(f"{k}: {before.get(k, state.get(k))!r} there, "
                          f"{now.get(k, [str(d) for d in data] if k == 'data' else None)!r} now" for k in diff[:4])
        raise InputError(f"checkpoint {ckpt} was made with other settings ({', '.join(diff)}): {shown}. Resume with "
                         "the same settings, or pass --no-resume (or delete it) to start again")


def _read_checkpoint(ckpt: Path, cfg: TrainConfig, data: list) -> dict:
    """The state saved in ``ckpt`` (FileFormatError when unreadable), checked to be of this run (:func:`_same_run`)."""
    try:  # tensors and plain values only: a checkpoint cannot run code when it is loaded
        state = torch.load(ckpt, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, OSError, ValueError, zipfile.BadZipFile) as exc:
        raise FileFormatError(f"checkpoint {ckpt} cannot be read ({type(exc).__name__}); delete it to start "
                              "again") from None
    if not isinstance(state, dict):
        raise FileFormatError(f"checkpoint {ckpt} is not a training checkpoint; delete it to start again")
    _same_run(ckpt, state, cfg, data)
    return state


def train_detector(
    data: list[str | os.PathLike],
    out: str | os.PathLike,
    cfg: TrainConfig = TrainConfig(),  # noqa: B008 (frozen: one shared default is safe)
    *,
    val: str | os.PathLike | None = None,
    resume: bool = True,
    overwrite: bool = False,
    progress: bool = True,
    log=print,
) -> dict[str, Any]:
    """Train on the COCO folders ``data`` and write ``out`` (ONNX) + its sidecar; returns a summary.

    A checkpoint ``<out>.ckpt`` is written after every epoch; when it exists (and ``resume``),
    training continues from it. It is removed once the ONNX file is written. An existing ``out``
    (or its sidecar) is refused before training unless ``overwrite``. With ``cfg.workers`` the sample
    workers are spawned processes (a fork of a process with threads can deadlock), so a script that
    calls this needs the usual ``if __name__ == "__main__":`` guard.
    """


    if not data:
        raise InputError("no training data given")
    out = Path(out)
    check_output(out, overwrite=overwrite, suffixes=(".onnx",), what="model file")
    check_output(out.with_suffix(".json"), overwrite=overwrite, what="model sidecar")
    with exclusive(out, message=f"another training run is writing {out}; wait for it or choose another --out"):
        return _train_locked(data, out, cfg, val=val, resume=resume, overwrite=overwrite, progress=progress, log=log)


def _train_locked(data: list, out: Path, cfg: TrainConfig, *, val, resume: bool, overwrite: bool, progress: bool,
                  log) -> dict[str, Any]:
    """:func:`train_detector` once its outputs are checked and locked for this run."""
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    train_sets = [load_coco(d) for d in data]
    val_set = load_coco(val) if val is not None else None
    frames = _Frames(train_sets, cfg, train=True)
    if len(frames) == 0:
        raise InputError(f"the training data {', '.join(map(str, data))} has no images")
    net = ConeNet(stride=cfg.stride, hidden=cfg.hidden, hidden_boxes=cfg.hidden_boxes, blocks=cfg.blocks,
                  stem_blocks=cfg.stem_blocks)
    if cfg.init is not None:
        load_onnx_weights(net, cfg.init)
    device = _device(cfg.device)
    net = net.to(device, memory_format=torch.channels_last)  # type: ignore[call-overload]  # torch's stubs lack memory_format; much faster convolutions on CPU
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    steps_per_epoch = math.ceil(frames.epoch_size() / cfg.batch_size)
    total_steps = steps_per_epoch * cfg.epochs if cfg.max_steps is None else min(cfg.max_steps, steps_per_epoch * cfg.epochs)

    def lr_at(step: int) -> float:
        if step < cfg.warmup_iters:
            return cfg.lr * (step + 1) / cfg.warmup_iters
        t = (step - cfg.warmup_iters) / max(1, total_steps - cfg.warmup_iters)
        return cfg.lr * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(1.0, t))))

    ckpt = out.with_name(out.name + ".ckpt")
    start_epoch, step, history, elapsed = 0, 0, [], 0.0
    if resume and ckpt.is_file():
        state = _read_checkpoint(ckpt, cfg, data)
        net.load_state_dict(state["model"])
        opt.load_state_dict(state["optim"])
        start_epoch, step, history, elapsed = state["epoch"], state["step"], state["history"], state["elapsed"]
        log(f"resuming from {ckpt} at epoch {start_epoch}")
    t_start = time.perf_counter() - elapsed
    batches = _EpochBatches()
    # sample workers are spawned, not forked (a fork of a process with threads can deadlock), and live for
    # the whole run; each batch names its epoch, so a worker makes any epoch's samples
    loader = torch.utils.data.DataLoader(frames, batch_sampler=batches, num_workers=cfg.workers, collate_fn=_stack,
                                         worker_init_fn=_one_thread, pin_memory=device.type == "cuda",
                                         multiprocessing_context="spawn" if cfg.workers else None,
                                         persistent_workers=cfg.workers > 0)
    for epoch in range(start_epoch, cfg.epochs):
        if step >= total_steps:
            break
        order = frames.epoch_order(epoch)
        net.train()
        if cfg.init is not None:
            _freeze_bn(net)
        sums: dict[str, float] = {}
        nb = 0
        batches.batches = [[(epoch, int(i)) for i in order[s : s + cfg.batch_size]]
                           for s in range(0, len(order), cfg.batch_size)]
        bar = tqdm(loader, total=len(batches), desc=f"epoch {epoch + 1}/{cfg.epochs}", disable=not progress,
                   leave=False)
        for batch in bar:
            x, *targets = (t.to(device, non_blocking=True) for t in batch)
            x = x.contiguous(memory_format=torch.channels_last)
            for g in opt.param_groups:
                g["lr"] = lr_at(step)
            loss, parts = detection_loss(net(x), *targets)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 10.0)
            opt.step()
            step += 1
            nb += 1
            for k, v in {"loss": loss.item(), **parts}.items():
                sums[k] = sums.get(k, 0.0) + v
            bar.set_postfix(loss=f"{sums['loss'] / nb:.3f}")
            if step >= total_steps:
                break
        entry = {"epoch": epoch + 1, "step": step, **{k: v / max(nb, 1) for k, v in sums.items()},
                 "elapsed_s": time.perf_counter() - t_start}
        if val_set is not None and ((epoch + 1) % 5 == 0 or epoch + 1 == cfg.epochs or step >= total_steps):
            entry["val_map50"] = _eval_map(net, val_set, cfg)
        history.append(entry)
        buf = io.BytesIO()  # torch's own file writer reports a full disk as a RuntimeError: write it ourselves
        torch.save({"model": net.state_dict(), "optim": opt.state_dict(), "epoch": epoch + 1, "step": step,
                    "history": history, "elapsed": time.perf_counter() - t_start, "config": asdict(cfg),
                    "data": [str(d) for d in data]}, buf)
        atomic_write(ckpt, buf.getvalue(), overwrite=True)  # the run's own checkpoint, replaced every epoch
        log(json.dumps(entry))
    train_time = time.perf_counter() - t_start
    meta = {
        "score_threshold": cfg.score_threshold,
        "training": {
            "data": [str(d) for d in data],
            "tracks": sorted({str(im.get("track")) for d in train_sets for im in d.images}),
            "frames": len(frames),
            "frames_per_data": [len(d) for d in train_sets],
            "val": str(val) if val is not None else None,
            "config": asdict(cfg),
            "steps": step,
            "train_time_s": round(train_time, 1),
            "hardware": _hardware(cfg, device),
            "torch": torch.__version__,
            "history": history,
        },
    }
    export_onnx(net.to("cpu", memory_format=torch.contiguous_format), out, cfg.input_size, meta, overwrite=overwrite)
    ckpt.unlink(missing_ok=True)
    return {"model": str(out), "steps": step, "train_time_s": train_time, "history": history}
