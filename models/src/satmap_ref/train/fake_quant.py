"""Int8 weight fake-quantisation for quantisation-aware fine-tuning: the same rounding the
runtime's `--precision int8` compile applies (`runtime/translate/src/int8_weights.rs`: `w / s`
in f32, rounded half away from zero), put on the model's weights as a parametrisation so that
training sees it, with a straight-through gradient.

The compile's rule, mirrored here per parameter: a tensor of at least `MIN_INT8_ELEMENTS`
elements, with at least two axes longer than 1 and at least `MIN_CHANNEL_ELEMENTS` values per
output channel, is stored as int8 with one symmetric scale per output channel
(`max |w| / 127`, -127..=127). Output channels are axis 0 of every torch weight we hold (Linear
`[out, in]`, Conv2d `[O, I, kh, kw]`, MultiheadAttention's `in_proj_weight` `[3C, C]`,
Embedding `[N, C]`), and the compile's axis for the same tensor in the exported graph.

Per-channel symmetric rounding commutes with a per-channel factor, so a BatchNorm folded into its
convolution at export keeps a snapped kernel on its grid. Where the exported graph splits a
weight along its input axis (a concatenated input) or folds it with a constant, the compile's
grid differs and it rounds those few tensors again. Weights with fewer than 16 inputs a channel
are stored f32 by the compile (so not rounded here) but quantised by the engine at load in a
W8A8 bundle: five small layers of `test` (k = 8) whose rounding this fine-tuning does not see.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn.utils import parametrize

#: As `int8_weights::MIN_INT8_ELEMENTS`.
MIN_INT8_ELEMENTS = 64
#: As `int8_weights::MIN_CHANNEL_ELEMENTS`.
MIN_CHANNEL_ELEMENTS = 16
#: Largest stored magnitude: -127..=127, -128 unused.
Q_MAX = 127

#: Parameters the export folds with constants into other tensors (the decoder's queries, their
#: reference points and first self-attention, the BEV positional encoding): the graph never
#: holds them, the compile rounds what they fold into on that tensor's own grid (or keeps it f32:
#: the reference points), so they are trained unquantised.
FOLDED_AT_EXPORT = (
    "positional_encoding.",
    "instance_embedding.",
    "pts_embedding.",
    "transformer.reference_points.",
    "decoder.layers.0.attentions.0.attn.in_proj_weight",
    # Read by the image encoder stage as its own Parameters, past the parametrisation; the graph
    # holds `level_embeds[0:1]` (`[1, C]`: kept f32) and `cams_embeds` rows (rounded by the
    # compile on their own grid).
    "transformer.cams_embeds",
    "transformer.level_embeds",
)


def stored_as_int8(shape: torch.Size) -> bool:
    """Whether the compile stores a weight of `shape` (output channels on axis 0) as int8."""
    numel = 1
    for d in shape:
        numel *= d
    long_axes = sum(1 for d in shape if d > 1)
    return (len(shape) >= 2 and numel >= MIN_INT8_ELEMENTS and long_axes >= 2
            and shape[0] > 0 and numel // shape[0] >= MIN_CHANNEL_ELEMENTS)


def channel_scales(w: torch.Tensor) -> torch.Tensor:
    """One scale per output channel: `max |w| / 127` over the channel (1 for an all-zero one),
    computed from the weight without a gradient, as the compile computes it."""
    with torch.no_grad():
        m = w.detach().abs().reshape(w.shape[0], -1).amax(dim=1)
        return torch.where(m > 0, m / Q_MAX, torch.ones_like(m)).to(torch.float32)


def compile_rounding(w: torch.Tensor) -> torch.Tensor:
    """`int8_weights::quantize_per_channel` and the widening, in f32: `q = round(w / s)` half
    away from zero (Rust's `f32::round`; torch's `round` and fake-quantisation round half to
    even and multiply by `1 / s`), clamped to +-127, then `q * s`. No gradient."""
    with torch.no_grad():
        s = channel_scales(w).reshape(-1, *([1] * (w.dim() - 1)))
        r = w.detach().float() / s
        q = (torch.sign(r) * torch.floor(r.abs() + 0.5)).clamp(-Q_MAX, Q_MAX)
        return (q * s).to(w.dtype)


class Int8Weight(nn.Module):
    """The parametrisation: `w -> compile_rounding(w)` per output channel, with the
    straight-through gradient (the identity's)."""

    def forward(self, w: torch.Tensor) -> torch.Tensor:
        # `r + (w - w)`: exactly r in value (w + (r - w) may round), the identity's gradient.
        return compile_rounding(w) + (w - w.detach())


def attach(model: nn.Module) -> list[str]:
    """Fake-quantise every parameter the compile stores as int8 as it is (not those in
    [`FOLDED_AT_EXPORT`]); returns their names."""
    # Collected first: registering adds modules to the tree being walked.
    found = [(mod_name, mod, p_name)
             for mod_name, mod in model.named_modules()
             for p_name, p in mod.named_parameters(recurse=False)
             if p.is_floating_point() and stored_as_int8(p.shape)
             and not any(f in f"{mod_name}.{p_name}" for f in FOLDED_AT_EXPORT)]
    for _, mod, p_name in found:
        parametrize.register_parametrization(mod, p_name, Int8Weight())
    return [f"{m}.{p}" if m else p for m, _, p in found]


def snap(model: nn.Module) -> int:
    """Remove the parametrisations, leaving each weight on its int8 grid (so the compile's
    rounding gives those values back); returns how many were snapped."""
    snapped = 0
    for mod in list(model.modules()):
        if parametrize.is_parametrized(mod):
            for p_name in list(mod.parametrizations.keys()):
                parametrize.remove_parametrizations(mod, p_name, leave_parametrized=True)
                snapped += 1
    return snapped


class ActivationQuant:
    """Per-tensor symmetric fake-quantisation of the inputs of the linear layers and
    convolutions whose weights are fake-quantised: what `compile --calibrate` then computes in
    int8 (abs-max over training frames, `abs_max / 127` a step). Forward pre-hooks: while
    `observing`, each records the largest `|x|` its module's input reached; afterwards each
    rounds its input to that range's grid (the gradient straight through inside the range, zero
    outside). MultiheadAttention's input projections are plain matmuls inside its forward and
    are not covered (their sensitivity is among the smallest, docs/int8.md)."""

    def __init__(self, model: nn.Module, weight_names: list[str]):
        wanted = {n.rsplit(".", 1)[0] for n in weight_names if n.endswith(".weight")}
        self.modules = {name: mod for name, mod in model.named_modules()
                        if name in wanted and isinstance(mod, (nn.Linear, nn.Conv2d))}
        self.abs_max: dict[str, float] = {}
        self.observing = True
        for name, mod in self.modules.items():
            mod.register_forward_pre_hook(self._hook(name))

    def _hook(self, name: str):
        def hook(_mod: nn.Module, args: tuple) -> tuple | None:
            x = args[0]
            if self.observing:
                m = float(x.detach().abs().amax())
                self.abs_max[name] = max(self.abs_max.get(name, 0.0), m)
                return None
            m = self.abs_max.get(name, 0.0)
            if m <= 0.0:
                return None
            q = torch.fake_quantize_per_tensor_affine(x, m / Q_MAX, 0, -Q_MAX, Q_MAX)
            return (q, *args[1:])
        return hook

    def freeze(self, abs_max: dict[str, float] | None = None) -> None:
        """Stop observing: quantise from now on with the recorded ranges (or `abs_max`, a
        checkpoint's)."""
        if abs_max is not None:
            self.abs_max = dict(abs_max)
        self.observing = False
