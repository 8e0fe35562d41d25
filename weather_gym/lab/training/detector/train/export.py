"""ConeNet to ONNX and back: :func:`export_onnx` (with the sidecar's metadata and the FLOP count) and
:func:`load_onnx_weights`, which starts a net from a shipped model (also a deeper one: added blocks
start as the identity).

Example:
    >>> from weather_gym.lab.training.detector.conenet import ConeNet
    >>> count_flops(ConeNet(4), (64, 32)) > 0
    True
"""

from __future__ import annotations

import io
import math
import os
import warnings
from pathlib import Path
from typing import Any

import torch

from weather_gym.core._io import atomic_write, atomic_write_json, check_output
from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import FileFormatError, MissingInputError
from weather_gym.lab.training.detector.conenet import ConeNet, ConeNetExport, DWBlock, layout
from weather_gym.perception.onnx_detector import load_model_metadata


# ----------------------------------------------------------------------------------- export
def _hidden_text(net: ConeNet) -> str:
    return ", hidden-cone heads and boxes" if net.hidden_boxes else ", hidden-cone heads" if net.hidden else ""


def count_flops(net: ConeNet, input_size: tuple[int, int]) -> int:
    """FLOPs (2 x multiply-adds) of one forward pass at ``input_size``, counted by torch."""
    from torch.utils.flop_counter import FlopCounterMode

    w, h = input_size
    with torch.no_grad(), FlopCounterMode(display=False) as fc:
        ConeNetExport(net).eval()(torch.zeros(1, 3, h, w))
    return int(fc.get_total_flops())


def export_onnx(net: ConeNet, path: str | os.PathLike, input_size: tuple[int, int], meta: dict | None = None, *,
                overwrite: bool = False) -> Path:
    """Export ``net`` (with sigmoid + peak filter) to ONNX with a dynamic batch, plus its JSON sidecar.

    Both files are written safely (``weather_gym.core._io``); existing ones only with ``overwrite``.
    """
    import onnx

    path = Path(path)
    sidecar_path = path.with_suffix(".json")
    for p in (path, sidecar_path):
        check_output(p, overwrite=overwrite, what="model file")
    w, h = input_size
    model = ConeNetExport(net.eval()).eval()
    buf = io.BytesIO()  # made in memory, then written by the safe writer: a full disk is an OutputPathError
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(model, torch.zeros(1, 3, h, w), buf, input_names=["images"],  # type: ignore[arg-type]  # one input tensor and a file object: torch takes both
                          output_names=["output"], dynamic_axes={"images": {0: "batch"}, "output": {0: "batch"}},
                          opset_version=17, dynamo=False)
    onnx.checker.check_model(onnx.load_from_string(buf.getvalue()))
    atomic_write(path, buf.getvalue(), overwrite=overwrite)
    sidecar = {
        "format": "weather-gym cone detector v1",
        "architecture": f"ConeNet (CenterNet-style, stride {net.stride}{_hidden_text(net)})",
        "input_size": [w, h],
        "input": "images: float32 (batch, 3, H, W) RGB 0..255, letterboxed (pad 114, centred)",
        "output": f"output: (batch, C+4, H/{net.stride}, W/{net.stride}) = peak-filtered class scores, box w/h (input px), centre offset",
        "classes": list(CONE_CLASSES),
        "stride": net.stride,
        "layout": net.arch,
        "params": int(sum(p.numel() for p in net.parameters())),
        "flops": count_flops(net, input_size),
        **(meta or {}),
    }
    atomic_write_json(sidecar_path, sidecar, indent=2, overwrite=overwrite)
    return path


# ----------------------------------------------------------------------------------- start weights
def load_onnx_weights(net: ConeNet, path: str | os.PathLike) -> ConeNet:  # noqa: C901 (ONNX graph checks, one per failure mode)
    """Load the weights of a ConeNet ONNX export (``export_onnx``) into ``net`` and return it.

    The export folds each batch norm into its convolution, so the convolutions get the folded weights
    and each batch norm becomes the identity with the folded bias (mean 0, variance 1 - eps, scale 1);
    train such a net with its batch norms in eval mode (``train_detector`` does with ``init``).
    Convolutions are matched in execution order and checked by shape. A stride-2 ``net`` can start
    from a stride-4 model: the shared layers get its weights, the finer pyramid level starts as the
    identity (``ConeNet``) and the size outputs are rescaled to the finer grid. A hidden-cone ``net``
    can start from a model without that head: its head starts as a copy of the main head, its
    heatmaps from the prior; a net with hidden-cone boxes can start from one with the hidden-cone
    heatmaps alone (the box outputs start from their prior). A net with more residual blocks (``blocks``,
    ``stem_blocks``; the file's layout is its sidecar's ``layout``) starts as the file's model, each added
    block as the identity.
    """
    import onnx
    from onnx import numpy_helper

    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"start model {path} does not exist")
    file_layout = _file_layout(path)
    if file_layout != net.arch:  # a deeper net: load the file into its own layout, then grow (one read)
        return _grow(net, file_layout, path)
    try:
        model = onnx.load(str(path))
    except Exception as exc:  # noqa: BLE001 - onnx raises several types for a bad file
        raise FileFormatError(f"{path} is not an ONNX model ({type(exc).__name__})") from None
    inits = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
    for node in model.graph.node:  # the exporter shares equal weights through Identity nodes
        if node.op_type == "Identity" and node.input[0] in inits:
            inits[node.output[0]] = inits[node.input[0]]
    onnx_convs = [n for n in model.graph.node if n.op_type == "Conv"]
    order: list[torch.nn.Conv2d] = []
    hooks = [m.register_forward_hook(lambda mod, *_: order.append(mod)) for m in net.modules()
             if isinstance(m, torch.nn.Conv2d)]
    w, h = 128, 64
    with torch.no_grad():
        net.eval()(torch.zeros(1, 3, h, w))
    for hk in hooks:
        hk.remove()
    if net.hidden and len(order) == len(onnx_convs) + 3:  # no hidden-cone head (2 convs + output) in the file
        plain = load_onnx_weights(ConeNet(net.num_classes, stride=net.stride), path)
        missing, unexpected = net.load_state_dict(plain.state_dict(), strict=False)
        if unexpected or any(not k.startswith(("head_hidden.", "out_hidden.")) for k in missing):
            raise FileFormatError(f"{path}: not a ConeNet export that a hidden-cone ConeNet can start from")
        net.head_hidden.load_state_dict(plain.head.state_dict())
        return net
    last = inits.get(onnx_convs[-1].input[1]) if onnx_convs else None
    if (net.hidden_boxes and len(order) == len(onnx_convs) and last is not None
            and last.shape[0] == net.num_classes):  # hidden-cone heatmaps in the file, but not their boxes
        heads = load_onnx_weights(ConeNet(net.num_classes, stride=net.stride, hidden=True), path)
        state = {k: v for k, v in heads.state_dict().items() if not k.startswith("out_hidden.")}
        missing, unexpected = net.load_state_dict(state, strict=False)
        if unexpected or any(not k.startswith("out_hidden.") for k in missing):
            raise FileFormatError(f"{path}: not a ConeNet export that a ConeNet with hidden-cone boxes can start from")
        with torch.no_grad():  # the heatmaps as they were; the boxes start from the prior (size 1 cell, mid-cell)
            net.out_hidden.weight[: net.num_classes] = heads.out_hidden.weight
            net.out_hidden.bias[: net.num_classes] = heads.out_hidden.bias  # type: ignore[index, assignment]  # a Conv2d made with a biass
        return net
    if len(order) != len(onnx_convs) and net.stride == 2:
        coarse = load_onnx_weights(ConeNet(net.num_classes, stride=4), path)
        missing, unexpected = net.load_state_dict(coarse.state_dict(), strict=False)
        if unexpected or any(not k.startswith(("lateral_fine.", "smooth_fine.")) for k in missing):
            raise FileFormatError(f"{path}: not a ConeNet export that a stride-2 ConeNet can start from")
        for m in [*net.lateral_fine.modules(), *net.smooth_fine.modules()]:  # the fresh level's batch norms:
            if isinstance(m, torch.nn.BatchNorm2d):  # identity, as the loaded ones
                m.running_mean.zero_()  # type: ignore[union-attr]  # a BatchNorm2d tracks its running stats
                m.running_var.fill_(1.0 - m.eps)  # type: ignore[union-attr]  # a BatchNorm2d tracks its running stats
        with torch.no_grad():  # log(w / 4) -> log(w / 2)
            net.out.bias[net.num_classes : net.num_classes + 2] += math.log(2.0)  # type: ignore[index]  # a Conv2d made with a bias
        return net
    if len(order) != len(onnx_convs):
        raise FileFormatError(f"{path}: {len(onnx_convs)} convolutions, but ConeNet has {len(order)}: not a ConeNet export")
    bn_after = {}
    for mod in net.modules():
        if isinstance(mod, torch.nn.Sequential):
            kids = list(mod)
            for a, b in zip(kids, kids[1:], strict=False):
                if isinstance(a, torch.nn.Conv2d) and isinstance(b, torch.nn.BatchNorm2d):
                    bn_after[a] = b
    with torch.no_grad():
        for conv, node in zip(order, onnx_convs, strict=True):
            weight = inits.get(node.input[1])
            bias = inits.get(node.input[2]) if len(node.input) > 2 else None
            if weight is None or tuple(weight.shape) != tuple(conv.weight.shape):
                raise FileFormatError(f"{path}: convolution {node.name} does not match ConeNet's {tuple(conv.weight.shape)}")
            conv.weight.copy_(torch.from_numpy(weight.copy()))
            bn = bn_after.get(conv)
            if bn is not None:
                bn.running_mean.zero_()  # type: ignore[union-attr]  # a BatchNorm2d tracks its running stats
                bn.running_var.fill_(1.0 - bn.eps)  # type: ignore[union-attr]  # a BatchNorm2d tracks its running stats
                bn.weight.fill_(1.0)
                bn.bias.copy_(torch.from_numpy(bias.copy()) if bias is not None else torch.zeros_like(bn.bias))
            elif conv.bias is not None and bias is not None:
                conv.bias.copy_(torch.from_numpy(bias.copy()))
    return net


def _file_layout(path: Path) -> dict[str, Any]:
    """The ConeNet layout of a model file, from its sidecar's ``layout`` (files without one: the default)."""
    default = layout()
    found = load_model_metadata(path).get("layout", default)
    if not isinstance(found, dict) or set(found) != set(default):
        raise FileFormatError(f"model sidecar {path.with_suffix('.json')}: 'layout' must have the keys "
                              f"{sorted(default)}, got {found!r}")
    return found


def _grow(net: ConeNet, file_layout: dict[str, Any], path: Path) -> ConeNet:
    """Load a model file with fewer residual blocks into ``net`` (deeper, else the same): the shared layers
    get its weights, each added block starts as the identity (its last batch norm's scale and shift at 0), so
    ``net`` starts as the file's model and fine-tuning gives the new blocks their part."""
    same = file_layout["widths"] == list(net.widths) and file_layout["neck"] == net.neck
    deeper = all(a >= b for a, b in zip(net.blocks, file_layout["blocks"], strict=True)) and \
        net.stem_blocks >= file_layout["stem_blocks"]
    if not (same and deeper):
        raise FileFormatError(f"{path}: its ConeNet layout {file_layout} cannot start a net with {net.arch} (only added "
                              "residual blocks, same widths and neck)")
    base = ConeNet(net.num_classes, widths=tuple(file_layout["widths"]), blocks=tuple(file_layout["blocks"]),
                   neck=file_layout["neck"], stem_blocks=file_layout["stem_blocks"], stride=net.stride, hidden=net.hidden,
                   hidden_boxes=net.hidden_boxes)
    load_onnx_weights(base, path)
    missing, unexpected = net.load_state_dict(base.state_dict(), strict=False)
    added = {f"stages.{i}.{j}" for i, (a, b) in enumerate(zip(net.blocks, file_layout["blocks"], strict=True))
             for j in range(b + 1, a + 1)} | {f"stem_refine.{j}" for j in range(file_layout["stem_blocks"], net.stem_blocks)}
    if unexpected or any(not k.startswith(tuple(f"{a}." for a in added)) for k in missing):
        raise FileFormatError(f"{path}: not a ConeNet export that a net with {net.arch} can start from")
    with torch.no_grad():
        for name, mod in net.named_modules():
            if name in added and isinstance(mod, DWBlock):
                mod.pw[1].weight.zero_()  # type: ignore[operator]  # pw[1] is a BatchNorm2d
                mod.pw[1].bias.zero_()  # type: ignore[operator]  # pw[1] is a BatchNorm2d
    return net
