"""Export-friendly sampling: bilinear sampling as one Gather of the four corners plus weights
(replaces `grid_sample`, which tract runs as a slow reference op), and bilinear resizing as two
constant matrices (replaces `Resize`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

# The committed vectors of the runtime's native corner-sum kernel (`kernel_golden`).
KERNEL_GOLDEN = Path(__file__).resolve().parents[2] / "golden" / "kernels" / "weighted_axis_sum.safetensors"


def bilinear_gather_sum(
    value: torch.Tensor, loc: torch.Tensor, attn: torch.Tensor, h: int, w: int
) -> torch.Tensor:
    """Multi-head deformable sampling over one level, the same math as
    `grid_sample(value, 2 * loc - 1, align_corners=False, padding_mode="zeros")` followed by the
    attention-weighted sum over points.

    value: [h * w, heads, dh] (row-major map); loc: [N, heads, P, 2] normalised (x, y) in [0, 1];
    attn: [N, heads, P]. Returns [N, heads * dh]."""
    hw, heads, dh = value.shape
    n, _, p, _ = loc.shape
    v = value.permute(1, 0, 2).reshape(heads * hw, dh)
    x = loc[..., 0] * float(w) - 0.5
    y = loc[..., 1] * float(h) - 0.5
    x0 = torch.floor(x)
    y0 = torch.floor(y)
    fx = x - x0
    fy = y - y0
    x1 = x0 + 1.0
    y1 = y0 + 1.0
    gx = 1.0 - fx
    gy = 1.0 - fy
    xs = torch.cat([x0, x1, x0, x1], dim=-1)  # [N, heads, 4P]
    ys = torch.cat([y0, y0, y1, y1], dim=-1)
    wts = torch.cat([gx * gy, fx * gy, gx * fy, fx * fy], dim=-1)
    inside = (xs >= 0.0) & (xs <= float(w - 1)) & (ys >= 0.0) & (ys <= float(h - 1))
    a = attn.repeat(1, 1, 4)
    wts = wts * a * inside.to(wts.dtype)
    # The flat index is built in f32 (exact: integers below 2^24) and cast once: tract's
    # broadcasting i64 arithmetic is ~10x slower than the f32 path.
    xi = torch.clamp(xs, 0.0, float(w - 1))
    yi = torch.clamp(ys, 0.0, float(h - 1))
    head_off = (torch.arange(heads, dtype=torch.float32) * float(hw)).view(1, heads, 1)
    flat = (yi * float(w) + xi + head_off).to(torch.int64)  # [N, heads, 4P]
    g = v[flat.reshape(-1)].reshape(n, heads, 4 * p, dh)
    out = (g * wts.unsqueeze(-1)).sum(dim=2)  # [N, heads, dh]
    return out.reshape(n, heads * dh)


def resize_matrix(n_in: int, n_out: int) -> np.ndarray:
    """[n_out, n_in] matrix of 1-D bilinear interpolation with PyTorch's
    `interpolate(mode="bilinear", align_corners=False)` coordinate rule."""
    m = np.zeros((n_out, n_in), dtype=np.float64)
    scale = n_in / n_out
    for d in range(n_out):
        src = max((d + 0.5) * scale - 0.5, 0.0)
        i0 = min(int(np.floor(src)), n_in - 1)
        i1 = min(i0 + 1, n_in - 1)
        l1 = src - i0
        m[d, i0] += 1.0 - l1
        m[d, i1] += l1
    return m.astype(np.float32)


class Resize2d(torch.nn.Module):
    """Bilinear resize of a [C, H, W] map to a fixed size as `A_h @ x @ A_w^T` (two MatMuls with
    constant matrices): same values as `F.interpolate(..., mode="bilinear",
    align_corners=False)`, no Resize op in the graph."""

    def __init__(self, in_hw: tuple[int, int], out_hw: tuple[int, int]):
        super().__init__()
        self.register_buffer("a_h", torch.from_numpy(resize_matrix(in_hw[0], out_hw[0])))
        self.register_buffer("a_w_t", torch.from_numpy(resize_matrix(in_hw[1], out_hw[1]).T.copy()))
        self.identity = tuple(in_hw) == tuple(out_hw)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.identity:
            return x
        return torch.matmul(torch.matmul(self.a_h, x), self.a_w_t)


def weighted_axis_sum(a: np.ndarray, b: np.ndarray, axis: int) -> np.ndarray:
    """The runtime's native corner-sum kernel (`engine_tract::ops::weighted_sum::WeightedAxisSum`,
    which replaces tract's `Mul -> ReduceSum` over a middle axis), bit for bit: the sum over
    `axis` of `a * b` (numpy broadcasting, f32, the axis kept as size 1), each output element
    starting at 0.0 and adding `a[k] * b[k]` for k ascending, a multiply then an add (numpy
    never fuses them)."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float32), np.asarray(b, dtype=np.float32))
    shape = a.shape[:axis] + (1,) + a.shape[axis + 1:]
    acc = np.zeros(shape, dtype=np.float32)
    for k in range(a.shape[axis]):
        acc = acc + np.take(a, [k], axis=axis) * np.take(b, [k], axis=axis)
    return acc


def bilinear_corner_sum(rows: np.ndarray, x: np.ndarray, y: np.ndarray, attn: np.ndarray,
                        h: int, w: int) -> np.ndarray:
    """The runtime's native sampler (`engine_tract::ops::bilinear::BilinearCornerSum`, which replaces
    the exported graph of `bilinear_gather_sum` from the pixel coordinates on), bit for bit: the
    same f32 operations in the same order as that graph, then `weighted_axis_sum`'s corner sum.

    rows: [heads * h * w, dh] (head-major map rows); x, y: [N, heads, P] pixel coordinates
    (`loc * size - 0.5`); attn: [N, heads, P]. Returns [N, heads, 1, dh]."""
    f32 = np.float32
    n, heads, _ = x.shape
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x1, y1 = x0 + f32(1.0), y0 + f32(1.0)
    gx, gy = f32(1.0) - fx, f32(1.0) - fy
    xs = np.concatenate([x0, x1, x0, x1], axis=-1)
    ys = np.concatenate([y0, y0, y1, y1], axis=-1)
    wc = np.concatenate([gx * gy, fx * gy, gx * fy, fx * fy], axis=-1)
    inside = (xs >= f32(0)) & (xs <= f32(w - 1)) & (ys >= f32(0)) & (ys <= f32(h - 1))
    wt = (wc * np.tile(attn, (1, 1, 4))) * inside.astype(f32)
    xi = np.minimum(np.maximum(xs, f32(0)), f32(w - 1))
    yi = np.minimum(np.maximum(ys, f32(0)), f32(h - 1))
    head_off = (np.arange(heads, dtype=f32) * f32(h * w)).reshape(1, heads, 1)
    flat = ((yi * f32(w) + xi) + head_off).astype(np.int64)
    g = rows[flat.reshape(-1)].reshape(n, heads, xs.shape[-1], rows.shape[1])
    return weighted_axis_sum(g, wt[..., None], 2)


def kernel_golden(seed: int = 0) -> dict[str, np.ndarray]:
    """Vectors the Rust kernel is checked against bit for bit (`tests/native_kernels.rs`): the
    sampler's shape in small, `[N=6, heads=3, corners x points=8, dh=5]` with per-corner weights
    `[6, 3, 8, 1]`, summed over axis 2; and the gathered form, rows of `data [20, 5]` picked by
    `indices [144]` and reshaped to that operand. Magnitudes span 1e-3..1e3 so that the
    summation order shows in the last bits."""
    rng = np.random.default_rng(seed)
    scale = np.float32(10.0) ** rng.integers(-3, 4, size=(6, 3, 8, 5)).astype(np.float32)
    a = (rng.standard_normal((6, 3, 8, 5)).astype(np.float32) * scale).astype(np.float32)
    b = rng.standard_normal((6, 3, 8, 1)).astype(np.float32)
    data = (rng.standard_normal((20, 5)).astype(np.float32)
            * np.float32(10.0) ** rng.integers(-3, 4, size=(20, 5)).astype(np.float32))
    indices = rng.integers(0, 20, size=6 * 3 * 8).astype(np.int64)
    # The whole sampler over a 5 x 4 map, 3 heads, 6 points: coordinates spread past every edge
    # (so corners fall outside and are clamped and masked), some exactly on integers.
    srng = np.random.default_rng(seed + 1)
    sh, sw, heads, pts, dh = 5, 4, 3, 6, 7
    rows = (srng.standard_normal((heads * sh * sw, dh))
            * np.float32(10.0) ** srng.integers(-2, 3, size=(heads * sh * sw, dh))).astype(np.float32)
    sx = srng.uniform(-1.7, sw + 0.7, size=(9, heads, pts)).astype(np.float32)
    sy = srng.uniform(-1.7, sh + 0.7, size=(9, heads, pts)).astype(np.float32)
    sx[0, 0, :3] = [0.0, -1.0, float(sw - 1)]
    sy[0, 0, :3] = [float(sh - 1), 0.0, -1.0]
    sattn = srng.uniform(0.0, 1.0, size=(9, heads, pts)).astype(np.float32)
    return {
        "sampler_rows": rows, "sampler_x": sx, "sampler_y": sy, "sampler_attn": sattn,
        "sampler_out": bilinear_corner_sum(rows, sx, sy, sattn, sh, sw),
        "a": a, "b": b, "out": weighted_axis_sum(a, b, 2),
        "data": data, "indices": indices,
        "gathered_out": weighted_axis_sum(data[indices].reshape(6, 3, 8, 5), b, 2),
    }


if __name__ == "__main__":
    from safetensors.numpy import save_file
    KERNEL_GOLDEN.parent.mkdir(parents=True, exist_ok=True)
    save_file(kernel_golden(), str(KERNEL_GOLDEN))
    print(f"wrote {KERNEL_GOLDEN}")
