"""The tables `make bench-peers` writes (`satmap_ref.peers`): the markdown block between the
markers of `docs/perf.md`, from the JSON of a run."""

from __future__ import annotations

from pathlib import Path


def _stage_names(bundle: Path | None = None) -> tuple[str, ...]:
    """The stages in pipeline order: the bundle manifest's (the onnxruntime worker must not
    import torch, whose ~600 MB would count as onnxruntime's resident set), else the model's."""
    if bundle is not None:
        import tomllib
        manifest = tomllib.loads((bundle / "manifest.toml").read_text())
        return tuple(s["name"] for s in manifest["stage"])
    from .model import STAGE_NAMES
    return STAGE_NAMES


ENGINES = ("satmap", "onnxruntime", "pytorch")
# Our runtime on the compiled NNEF form of the same stages (`<bundle>.satmap` beside the folder,
# what `satmap-sim compile` writes and the product ships): timed where that file exists.
COMPILED = "satmap-compiled"
# Ours in integer arithmetic (the bundle's W8A8 compiled form) and onnxruntime on the stages
# quantised by `satmap_ref.ort_int8`: timed where a bundle names its int8 forms (`--int8`).
SATMAP_INT8 = "satmap-int8"
ORT_INT8 = "onnxruntime-int8"
INT8_ENGINES = (SATMAP_INT8, ORT_INT8)


def _step_sum(med: dict[str, float]) -> float:
    """A frame's stage time: six cameras' image encoders plus the other stages once."""
    return sum(med[s] * (6 if s == "image_encoder" else 1) for s in med)


BEGIN = "<!-- bench-peers: begin (written by `make bench-peers`, do not edit) -->"
END = "<!-- bench-peers: end -->"


def write_markdown(path: Path, block: str) -> None:
    """Put `block` between the BEGIN/END markers of `path`, keeping the hand-written text
    around them; a file without markers gets a title and the block."""
    text = path.read_text() if path.exists() else ""
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        tail = rest.split(END, 1)[1]
    else:
        head, tail = "# Speed against onnxruntime and PyTorch\n\n", "\n"
    path.write_text(f"{head}{BEGIN}\n{block}{END}{tail}")


def markdown(result: dict, command: str) -> str:
    m = result["machine"]
    lines = [
        f"Written by `{command}` on {m['cpu']} ({m['cores']} cores, tract kernel family "
        f"`{m['kernel_family']}`). Medians of every timed repeat of every round, milliseconds; "
        "every engine in its own process, engines alternating. Inputs: each bundle's "
        "`reference.safetensors`. GFLOP: matmul/conv FLOPs of the reference stage. "
        "'% peak' = achieved GFLOP/s over the best large f32 matmul at that thread count. "
        "'x ORT' = our time over onnxruntime's (below 1 is faster). 'ours' reads the exported "
        "ONNX folder, as the peers do; 'ours compiled', where the bundle has one, the compiled "
        "NNEF form of the same stages (`<bundle>.satmap`, the form the runtime ships).",
        "",
    ]
    for t, p in result["peak"].items():
        by = ", ".join(f"{k} {v:.1f}" for k, v in p["gflops_by_library"].items())
        lines.append(f"- Peak at {t} thread(s): {p['gflops']:.1f} GFLOP/s, the best of a "
                     f"{p['n']}^3 f32 matmul through {by}.")
    lines.append("")
    for name, b in result["bundles"].items():
        for t, r in b["threads"].items():
            peak = result["peak"][t]["gflops"]
            med = r["median_ms"]
            # The compiled form's two columns, where it was timed (older results lack it).
            comp = COMPILED in med
            c_head, c_rule = (" ours compiled ms | compiled x ORT |", "---|---|") if comp else ("", "")
            lines += [f"### {name} (config `{b['config']}`), {t} thread(s)", "",
                      f"| stage | GFLOP | ours ms | ORT ms | PyTorch ms | x ORT | x PyTorch |{c_head} "
                      "% peak ours / ORT / PyTorch |",
                      f"|---|---|---|---|---|---|---|{c_rule}---|"]
            for s in _stage_names():
                gf = b["flops"][s] / 1e9
                o, x, y = med["satmap"][s], med["onnxruntime"][s], med["pytorch"][s]
                pct = " / ".join(f"{100 * gf / (v / 1e3) / peak:.0f}%" for v in (o, x, y))
                c = f" {med[COMPILED][s]:.2f} | {med[COMPILED][s] / x:.2f} |" if comp else ""
                lines.append(f"| {s} | {gf:.3f} | {o:.2f} | {x:.2f} | {y:.2f} | {o / x:.2f} | "
                             f"{o / y:.2f} |{c} {pct} |")
            sums = [_step_sum(med[e]) for e in ENGINES]
            step = r["satmap_step_median_ms"]
            step_txt = f"{step:.1f}" if step is not None else "n/a"
            c_sum = _step_sum(med[COMPILED]) if comp else 0.0
            c = f" {c_sum:.1f} | {c_sum / sums[1]:.2f} |" if comp else ""
            c_empty = " | |" if comp else ""
            lines.append(f"| frame: 6 x image_encoder + the rest | | {sums[0]:.1f} | "
                         f"{sums[1]:.1f} | {sums[2]:.1f} | {sums[0] / sums[1]:.2f} | "
                         f"{sums[0] / sums[2]:.2f} |{c} |")
            skipped = r["engines"]["satmap"].get("step_skipped")
            lines.append(f"| our whole step (`SatMap::step`, gather and decode included) | | "
                         f"{step_txt} | | | | |{c_empty} |")
            rss = " / ".join(f"{r['engines'][e]['max_rss_kib'] / 1024:.0f}" for e in ENGINES)
            lines += ["", f"Max RSS per process, MiB (ours / ORT / PyTorch): {rss}."]
            if comp:
                lines[-1] += (f" Ours on the compiled form: "
                              f"{r['engines'][COMPILED]['max_rss_kib'] / 1024:.0f} MiB.")
            if skipped:
                lines.append(f"Whole step not timed: {skipped}.")
            lines.append("")
            if SATMAP_INT8 in med:
                lines += int8_table(name, t, med)
    return "\n".join(lines) + "\n"


def int8_table(name: str, threads: int, med: dict) -> list[str]:
    """Ours and onnxruntime in int8 beside both in f32 (ours on the compiled form where it was
    timed, else the folder's)."""
    ours = med[COMPILED] if COMPILED in med else med["satmap"]
    cols = (ours, med[SATMAP_INT8], med["onnxruntime"], med[ORT_INT8])
    lines = [f"#### {name}, {threads} thread(s): int8", "",
             "| stage | ours f32 ms | ours int8 ms | ORT f32 ms | ORT int8 ms | "
             "ours int8 / ours f32 | ours int8 / ORT int8 |",
             "|---|---|---|---|---|---|---|"]
    for s in _stage_names():
        o, q, x, y = (c[s] for c in cols)
        lines.append(f"| {s} | {o:.2f} | {q:.2f} | {x:.2f} | {y:.2f} | {q / o:.2f} | "
                     f"{q / y:.2f} |")
    o, q, x, y = (_step_sum(c) for c in cols)
    lines += [f"| frame: 6 x image_encoder + the rest | {o:.1f} | {q:.1f} | {x:.1f} | {y:.1f} | "
              f"{q / o:.2f} | {q / y:.2f} |", ""]
    return lines


