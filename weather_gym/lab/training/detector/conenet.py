"""ConeNet: a small CenterNet-style cone detector in PyTorch (training only; the runtime uses ONNX).

The network sees a letterboxed RGB image (default 512x288) and predicts, on a grid of stride 4 (or 2):

* ``heat``  - one sigmoid heatmap per cone class; a cone is a local peak at its box centre,
* ``size``  - ``log(w / 4)``, ``log(h / 4)`` of the box (scale-free regression),
* ``offset`` - the sub-cell position of the centre (0..1 in each axis).

Backbone: a plain stride-2 3x3 conv at each scale (16-24-48-96-128 channels) followed by residual
depthwise-separable blocks (``blocks``: 1, 2, 2, 1 at strides 4-32; ``stem_blocks`` more at stride 2;
a deeper net can start from a shallower model's file, ``train.load_onnx_weights``); a top-down feature pyramid brings the stride 8/16/32 features back to
stride 4, where a depthwise-separable head predicts the 8 output channels. With ``stride=2`` the pyramid
goes one level further, to the stem's stride-2 features: two cones whose centres are 4-8 input pixels
apart (the rear cone of a start-line pair) then fall in separate cells, so the peak filter can keep
both where the net puts a peak on each (the shipped model often does not: docs/model_card.md,
"After v4"). The exported ONNX graph
also applies the sigmoid and a 3x3 max-pool peak filter (CenterNet's "NMS"), so the runtime only
thresholds peaks.

With ``hidden=True`` a second set of class heatmaps (its own depthwise-separable head) is trained only
on *hidden* cones: cones whose visible box touches the box of a nearer cone (the rear cone of a pair,
a cone behind another in a hairpin). Their peaks do not compete with the front cone's peak in the main
heatmap, so the rear cone gets its own peak; the size and offset outputs are shared. The export
peak-filters both sets and keeps, per class and cell, the larger score, so the ONNX output keeps the
same ``C+4`` channels and the runtime is unchanged (a duplicate of a front cone is removed by the box NMS).
With ``hidden_boxes=True`` the hidden-cone head also predicts the hidden cones' boxes, trained at every
cell near their centre, not only at it: the rear cone's centre is one to three cells from the front
cone's, and a hidden peak that lands beside it (or on the front cone) is trained to point at the rear
cone's box. Where a cell's hidden peak beats its main peak, the export reports the hidden box there
(measured from v5: training with these boxes finds more rear cones, reporting them changes nothing;
CHANGELOG.md, "Detector: after v5").

Example:
    >>> import torch
    >>> from weather_gym.lab.training.detector.conenet import ConeNet
    >>> net = ConeNet().eval()
    >>> out = net(torch.zeros(1, 3, 288, 512))
    >>> tuple(out.shape)  # (batch, 4 classes + 2 size + 2 offset, H/4, W/4)
    (1, 8, 72, 128)
    >>> tuple(ConeNet(stride=2).eval()(torch.zeros(1, 3, 288, 512)).shape)
    (1, 8, 144, 256)
    >>> tuple(ConeNet(stride=2, hidden=True).eval()(torch.zeros(1, 3, 288, 512)).shape)  # + 4 hidden-cone heatmaps
    (1, 12, 144, 256)
    >>> tuple(ConeNet(stride=2, hidden=True, hidden_boxes=True).eval()(torch.zeros(1, 3, 288, 512)).shape)
    (1, 16, 144, 256)
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from weather_gym.core.errors import InputError

NUM_CLASSES = 4
STRIDE = 4  # the default output stride
STRIDES = (2, 4)
OUT_CHANNELS = NUM_CLASSES + 4
DEFAULT_WIDTHS = (16, 24, 48, 96, 128)  # channels at strides 2, 4, 8, 16, 32
DEFAULT_BLOCKS = (1, 2, 2, 1)  # residual blocks at strides 4, 8, 16, 32
DEFAULT_NECK = 32
MAX_BLOCKS = 8
"""The most residual blocks at one stride (``blocks``, ``stem_blocks``): 4x the default's deepest stage; an
unbounded count built nets of gigabytes (``--blocks 1000,...``)."""
HEAT_PRIOR = 0.01  # initial heatmap probability (focal-loss bias init, as in CenterNet/RetinaNet)


def conv_bn(cin: int, cout: int, k: int = 3, s: int = 1, groups: int = 1, act: bool = True) -> nn.Sequential:
    layers: list[nn.Module] = [
        nn.Conv2d(cin, cout, k, s, k // 2, groups=groups, bias=False),
        nn.BatchNorm2d(cout),
    ]
    if act:
        layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


class DWBlock(nn.Module):
    """Residual depthwise-separable block: dw 3x3 -> pw 1x1, plus the input."""

    def __init__(self, ch: int) -> None:
        super().__init__()
        self.dw = conv_bn(ch, ch, 3, groups=ch)
        self.pw = conv_bn(ch, ch, 1, act=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(x + self.pw(self.dw(x)))


def dw_sep(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(conv_bn(cin, cin, 3, groups=cin), conv_bn(cin, cout, 1))


class ConeNet(nn.Module):
    """CenterNet-lite for cones. ``widths`` are the channels at strides 2, 4, 8, 16, 32; ``stride`` is
    the output grid's (4, or 2 for a finer grid that separates neighbouring cones); ``hidden`` adds the
    hidden-cone heatmaps (raw output ``C+4+C`` channels: heat, size, offset, hidden heat)."""

    def __init__(
        self,
        num_classes: int = NUM_CLASSES,
        widths: tuple[int, int, int, int, int] = DEFAULT_WIDTHS,
        blocks: tuple[int, int, int, int] = DEFAULT_BLOCKS,
        neck: int = DEFAULT_NECK,
        stride: int = STRIDE,
        hidden: bool = False,
        hidden_boxes: bool = False,
        stem_blocks: int = 0,
    ) -> None:
        super().__init__()
        if stride not in STRIDES:
            raise InputError(f"ConeNet stride must be one of {STRIDES}, got {stride}")
        self.num_classes = num_classes
        self.stride = stride
        if hidden_boxes and not hidden:
            raise InputError("hidden_boxes needs hidden=True (they are the hidden-cone head's boxes)")
        self.hidden = bool(hidden)
        self.hidden_boxes = bool(hidden_boxes)
        w = widths
        if len(widths) != 5 or len(blocks) != 4 or min(blocks) < 0 or stem_blocks < 0 or neck < 1 \
                or max(*blocks, stem_blocks) > MAX_BLOCKS:
            raise InputError(f"ConeNet needs 5 widths, 4 block counts in 0..{MAX_BLOCKS}, stem_blocks in 0..{MAX_BLOCKS} "
                             f"and neck >= 1; got "
                             f"widths={widths}, blocks={blocks}, stem_blocks={stem_blocks}, neck={neck}")
        self.widths, self.blocks = tuple(int(c) for c in widths), tuple(int(b) for b in blocks)
        self.neck, self.stem_blocks = int(neck), int(stem_blocks)
        self.stem = conv_bn(3, w[0], 3, 2)
        if stem_blocks:  # residual blocks at stride 2: the finest pyramid level sees more than one 3x3 conv
            self.stem_refine = nn.Sequential(*[DWBlock(w[0]) for _ in range(stem_blocks)])
        stages = []
        for i in range(4):
            stages.append(nn.Sequential(conv_bn(w[i], w[i + 1], 3, 2), *[DWBlock(w[i + 1]) for _ in range(blocks[i])]))
        self.stages = nn.ModuleList(stages)
        self.lateral = nn.ModuleList([conv_bn(c, neck, 1) for c in w[1:]])
        self.smooth = nn.ModuleList([dw_sep(neck, neck) for _ in range(3)])
        if stride == 2:  # one more pyramid level, from the stem; it starts as the identity (see below)
            self.lateral_fine = conv_bn(w[0], neck, 1)
            self.smooth_fine = dw_sep(neck, neck)
            nn.init.zeros_(self.smooth_fine[1][1].weight)  # type: ignore[index]  # Sequentials; zero-init residual: starts as the stride-4 features
        self.head = dw_sep(neck, neck)
        self.out = nn.Conv2d(neck, num_classes + 4, 1)
        nn.init.constant_(self.out.bias[:num_classes], float(torch.log(torch.tensor(HEAT_PRIOR / (1 - HEAT_PRIOR)))))  # type: ignore[index]  # a Conv2d made with a bias
        nn.init.zeros_(self.out.bias[num_classes:])  # type: ignore[index]  # a Conv2d made with a bias
        nn.init.normal_(self.out.weight, std=0.01)
        if self.hidden:
            self.head_hidden = dw_sep(neck, neck)
            self.out_hidden = nn.Conv2d(neck, num_classes + (4 if self.hidden_boxes else 0), 1)
            nn.init.constant_(self.out_hidden.bias[:num_classes], float(self.out.bias[0].detach()))  # type: ignore[index]  # a Conv2d made with a bias
            nn.init.normal_(self.out_hidden.weight, std=0.01)
            if self.hidden_boxes:  # log size 0 (as the main head starts), offset in the middle of the cell
                nn.init.zeros_(self.out_hidden.bias[num_classes:])  # type: ignore[index]  # a Conv2d made with a bias
                nn.init.constant_(self.out_hidden.bias[num_classes + 2 :], 0.5)  # type: ignore[index]  # a Conv2d made with a bias

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Raw outputs ``(B, C+4, H/s, W/s)``: heat logits, log size, offset (pre-sigmoid); with ``hidden``,
        then ``C`` hidden-cone heat logits; with ``hidden_boxes``, then the hidden cones' log size and their
        centre's offset from the cell in cells (linear: it may point a few cells away)."""
        feats = []
        x = stem = self.stem_refine(self.stem(x)) if self.stem_blocks else self.stem(x)
        for stage in self.stages:
            x = stage(x)
            feats.append(x)
        y = self.lateral[3](feats[3])
        for i in (2, 1, 0):
            lat = self.lateral[i](feats[i])
            y = F.interpolate(y, size=lat.shape[-2:], mode="nearest") + lat
            y = self.smooth[i](y)
        if self.stride == 2:
            y = F.interpolate(y, size=stem.shape[-2:], mode="nearest")
            y = y + self.smooth_fine(y + self.lateral_fine(stem))
        out = self.out(self.head(y))
        if self.hidden:
            out = torch.cat([out, self.out_hidden(self.head_hidden(y))], dim=1)
        return out

    @property
    def arch(self) -> dict[str, Any]:
        """The constructor's size arguments (``ConeNet(**net.arch, stride=..., ...)`` rebuilds the layout)."""
        return layout(self.widths, self.blocks, self.neck, self.stem_blocks)


def layout(widths: tuple[int, ...] = DEFAULT_WIDTHS, blocks: tuple[int, ...] = DEFAULT_BLOCKS,
           neck: int = DEFAULT_NECK, stem_blocks: int = 0) -> dict[str, Any]:
    """A ConeNet's size arguments as the sidecar's ``layout`` records them (the defaults: the shipped net's)."""
    return {"widths": [int(c) for c in widths], "blocks": [int(b) for b in blocks], "neck": int(neck),
            "stem_blocks": int(stem_blocks)}


def _peaks(heat: torch.Tensor) -> torch.Tensor:
    """``heat`` where it is a 3x3 local maximum, else 0 (CenterNet's peak filter)."""
    return heat * (F.max_pool2d(heat, 3, 1, 1) == heat).to(heat.dtype)


class ConeNetExport(nn.Module):
    """The graph that is exported to ONNX: input uint8-range float ``(B,3,H,W)`` RGB in 0..255.

    Output ``(B, C+4, H/s, W/s)`` for the net's stride ``s``: peak-filtered class probabilities (0 where not a 3x3 local
    maximum), box width/height in input pixels, centre offset in cells (0..1). A ``hidden`` net's two sets
    of heatmaps are peak-filtered each on its own and merged by the larger score per class and cell.
    """

    def __init__(self, net: ConeNet) -> None:
        super().__init__()
        self.net = net
        self.num_classes = net.num_classes

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        raw = self.net(x * (1.0 / 255.0))
        c = self.num_classes
        heat = torch.sigmoid(raw[:, :c])
        peaks = _peaks(heat)
        def box_size(log_size: torch.Tensor) -> torch.Tensor:  # input pixels
            return torch.exp(log_size.clamp(max=6.0)) * self.net.stride

        size = box_size(raw[:, c : c + 2])
        offset = torch.sigmoid(raw[:, c + 2 : c + 4])
        if self.net.hidden:
            hidden = _peaks(torch.sigmoid(raw[:, c + 4 : 2 * c + 4]))
            if self.net.hidden_boxes:  # a cell whose hidden-cone peak wins reports the hidden cone's box
                wins = hidden.amax(dim=1, keepdim=True) > peaks.amax(dim=1, keepdim=True)
                size = torch.where(wins, box_size(raw[:, 2 * c + 4 : 2 * c + 6]), size)
                offset = torch.where(wins, raw[:, 2 * c + 6 : 2 * c + 8], offset)
            peaks = torch.maximum(peaks, hidden)
        return torch.cat([peaks, size, offset], dim=1)
