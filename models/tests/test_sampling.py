"""The export rewrites compute the same math as the PyTorch ops they replace: four-corner
gather vs `grid_sample`, constant-matrix resize vs `interpolate`, reshape patch merging vs the
official strided slices, folded queue vs two-entry temporal self-attention."""

import numpy as np
import torch
import torch.nn.functional as F

from satmap_ref.bev import TemporalSelfAttention
from satmap_ref.sampling import Resize2d, bilinear_gather_sum
from satmap_ref.swin import PatchMerging


def _msda_grid_sample(value, loc, attn, h, w):
    """mmcv's `multi_scale_deformable_attn_pytorch` for one level."""
    hw, heads, dh = value.shape
    n, _, p, _ = loc.shape
    v = value.permute(1, 2, 0).reshape(heads, dh, h, w)
    grid = (2 * loc - 1).permute(1, 0, 2, 3)  # [heads, n, p, 2]
    s = F.grid_sample(v, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    out = (s * attn.permute(1, 0, 2).unsqueeze(1)).sum(-1)  # [heads, dh, n]
    return out.permute(2, 0, 1).reshape(n, heads * dh)


def test_bilinear_gather_equals_grid_sample():
    g = torch.Generator().manual_seed(0)
    h, w, heads, dh, n, p = 7, 5, 3, 4, 200, 6
    value = torch.randn(h * w, heads, dh, generator=g)
    loc = torch.rand(n, heads, p, 2, generator=g) * 1.6 - 0.3  # includes out-of-range points
    attn = torch.rand(n, heads, p, generator=g)
    ours = bilinear_gather_sum(value, loc, attn, h, w)
    ref = _msda_grid_sample(value, loc, attn, h, w)
    assert torch.abs(ours - ref).max() < 1e-5


def test_resize_matrices_equal_interpolate():
    g = torch.Generator().manual_seed(1)
    for (hi, wi), (ho, wo) in [((7, 4), (13, 7)), ((50, 25), (80, 40)), ((100, 50), (80, 40))]:
        x = torch.randn(1, 3, hi, wi, generator=g)
        ref = F.interpolate(x, size=(ho, wo), mode="bilinear", align_corners=False)
        ours = Resize2d((hi, wi), (ho, wo))(x)
        assert torch.abs(ours - ref).max() < 1e-5


def test_patch_merging_matches_official_order():
    torch.manual_seed(2)
    h, w, c = 6, 4, 5
    pm = PatchMerging(c, (h, w)).eval()
    x = torch.randn(h * w, c)
    xs = x.view(h, w, c)
    cat = torch.cat([xs[0::2, 0::2], xs[1::2, 0::2], xs[0::2, 1::2], xs[1::2, 1::2]], -1)
    ref = pm.reduction(pm.norm(cat.reshape(-1, 4 * c)))
    assert torch.allclose(pm(x), ref, atol=1e-6)


def test_folded_queue_equals_two_entry_attention():
    torch.manual_seed(3)
    d, heads, pts, bh, bw = 16, 4, 2, 6, 5
    tsa = TemporalSelfAttention(d, heads, pts, bh, bw).eval()
    q = torch.randn(bh * bw, d)
    pos = torch.randn(bh * bw, d)
    with torch.no_grad():
        ours = tsa(q, pos)
        qcat = torch.cat([q, q + pos], -1)
        value = tsa.value_proj(q).view(-1, heads, d // heads)
        off = tsa.sampling_offsets(qcat).view(-1, heads, 2, pts, 2)
        attn = tsa.attention_weights(qcat).view(-1, heads, 2, pts).softmax(-1)
        norm = torch.tensor([bw, bh], dtype=torch.float32)
        outs = []
        for e in range(2):
            loc = tsa.ref_2d.view(-1, 1, 1, 2) + off[:, :, e] / norm
            outs.append(_msda_grid_sample(value, loc, attn[:, :, e], bh, bw))
        ref = tsa.output_proj((outs[0] + outs[1]) / 2) + q
    assert torch.abs(ours - ref).max() < 1e-5
    assert np.isfinite(ours.numpy()).all()


def test_weighted_axis_sum_is_the_weighted_sum_in_a_fixed_order():
    from satmap_ref.sampling import kernel_golden, weighted_axis_sum
    g = kernel_golden()
    a, b = g["a"], g["b"]
    want = (a.astype(np.float64) * b.astype(np.float64)).sum(axis=2, keepdims=True)
    got = weighted_axis_sum(a, b, 2)
    assert got.shape == (6, 3, 1, 5) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
    # The order is part of the contract: summing k descending changes the last bits somewhere.
    rev = weighted_axis_sum(a[:, :, ::-1], b[:, :, ::-1], 2)
    assert not np.array_equal(got.view(np.uint32), rev.view(np.uint32))
    # The gathered form is the plain form on the gathered rows.
    gathered = g["data"][g["indices"]].reshape(6, 3, 8, 5)
    assert np.array_equal(g["gathered_out"], weighted_axis_sum(gathered, b, 2))


def test_committed_kernel_golden_is_current():
    from safetensors.numpy import load_file

    from satmap_ref.sampling import KERNEL_GOLDEN, kernel_golden
    committed = load_file(str(KERNEL_GOLDEN))
    fresh = kernel_golden()
    assert sorted(committed) == sorted(fresh)
    for k, v in fresh.items():
        assert committed[k].dtype == v.dtype and np.array_equal(
            committed[k].view(np.uint8), v.view(np.uint8)), k


def test_native_sampler_reference_equals_the_exported_sampler():
    """`bilinear_corner_sum` (the runtime kernel's bit-exact reference) computes what the
    exported `bilinear_gather_sum` computes, from the pixel coordinates on."""
    from satmap_ref.sampling import bilinear_corner_sum

    g = torch.Generator().manual_seed(4)
    h, w, heads, dh, n, p = 6, 9, 3, 4, 120, 5
    value = torch.randn(h * w, heads, dh, generator=g)
    loc = torch.rand(n, heads, p, 2, generator=g) * 1.6 - 0.3
    attn = torch.rand(n, heads, p, generator=g)
    ours = bilinear_gather_sum(value, loc, attn, h, w).numpy()
    rows = value.permute(1, 0, 2).reshape(heads * h * w, dh).numpy()
    x = (loc[..., 0] * float(w) - 0.5).numpy()
    y = (loc[..., 1] * float(h) - 0.5).numpy()
    ref = bilinear_corner_sum(rows, x, y, attn.numpy(), h, w).reshape(n, heads * dh)
    assert np.abs(ours - ref).max() < 1e-5
