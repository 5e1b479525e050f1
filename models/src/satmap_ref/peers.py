"""`make bench-peers`: the same stages on the same inputs through our runtime (`satmap-sim
bench-stages`), onnxruntime and PyTorch eager, side by side, at each thread count.

Every engine runs in a process of its own (so its peak resident set is its own), the engines
alternate round by round (so a slow spell of this shared machine hits them all), and each
stage's figure is the median of every timed repeat of every round. The inputs are the bundle's
`reference.safetensors` (one recorded frame); ONNX files are the bundle's own (ours runs them
too, and, where `<bundle>.satmap` sits beside the folder, its compiled form); PyTorch runs the
stage modules the export traced, with the bundle's weights. FLOPs per stage come from the
reference (`stage_table`: matmul/conv FLOPs, 2 per multiply-add); the peak is the best of a
large f32 matmul through NumPy's BLAS and through PyTorch's at the same thread count.

Output: `<out>.md` (the tables) and `<out>.json` (every figure). A command a person runs, never
a test: it measures wall time.

CLI: `python -m satmap_ref.peers --sim ../target/release/satmap-sim --bundle test=bundles/test
--bundle nano=build/nano --threads 1 2 --out ../docs/perf`; `python -m satmap_ref.peers worker
...` is one engine's process."""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

from .peers_report import (  # noqa: F401 (BEGIN, END re-exported for the tests)
    BEGIN, COMPILED, END, ENGINES, INT8_ENGINES, ORT_INT8, SATMAP_INT8, _stage_names, markdown,
    write_markdown)

PEAK_N = 2048
MODELS_ROOT = Path(__file__).resolve().parents[2]
# The weights each bundle was exported with: the committed trained default, else the seeded
# initialisation (`export --seed 0`).
DEFAULT_WEIGHTS = {"test": MODELS_ROOT / "weights" / "test_sat.safetensors"}


def _thread_env(threads: int) -> dict[str, str]:
    env = dict(os.environ)
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[k] = str(threads)
    return env


def _reference(bundle: Path) -> dict:
    from safetensors.numpy import load_file
    return load_file(str(bundle / "reference.safetensors"))


def _time_all(runs: list[tuple[str, object]], repeats: int) -> list[tuple[str, list[float]]]:
    """Every stage run once before any is timed, then each timed (after its own warm-up run),
    for an engine that loads the whole model at once (PyTorch here, ours in `satmap-sim
    bench-stages`): that load leaves the machine busy for a while, and the stage timed first
    paid for it in some processes. onnxruntime loads one stage's session before timing it."""
    for _, fn in runs:
        fn()
    return [(name, _time(repeats, fn)) for name, fn in runs]


def _time(repeats: int, fn) -> list[float]:
    fn()
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t) * 1e3)
    return out


def _max_rss_kib() -> int:
    """This process's peak resident set, KiB: `VmHWM`, which starts afresh at exec. Not
    `getrusage(RUSAGE_SELF).ru_maxrss`: Linux carries the parent's peak into a forked child's
    `ru_maxrss`, so every worker would report at least the driver's own peak."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return 0


def worker_onnxruntime(bundle: Path, threads: int, repeats: int) -> dict:
    import onnxruntime as ort
    ref = _reference(bundle)
    stages = []
    # One session at a time, loaded just before it is timed (so each load is one stage's): every
    # session owns a thread pool whose threads spin after a run, and with all five alive those
    # of the idle sessions took the cores from the timed one (`test`'s image encoder on two
    # threads 2.4 -> 6.4-11.1 ms when they were all loaded first).
    for name in _stage_names(bundle):
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads
        so.inter_op_num_threads = 1
        so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        sess = ort.InferenceSession(str(bundle / f"{name}.onnx"), so,
                                    providers=["CPUExecutionProvider"])
        feeds = {i.name: ref[f"{name}.{i.name}"] for i in sess.get_inputs()}
        stages.append((name, _time(repeats, lambda: sess.run(None, feeds))))
        del sess
    return {"engine": "onnxruntime", "version": ort.__version__, "threads": threads,
            "stages_ms": stages, "max_rss_kib": _max_rss_kib()}


def worker_pytorch(bundle: Path, config: str, weights: Path | None, threads: int,
                   repeats: int) -> dict:
    import torch
    torch.set_num_threads(threads)
    torch.set_num_interop_threads(1)
    from .config import get_config
    from .export import example_inputs, load_weights
    from .model import build_model
    cfg = get_config(config)
    model = build_model(cfg, 0)
    if weights is not None:
        load_weights(model, weights)
    model.eval()
    ref = _reference(bundle)
    runs = []
    from .export import stage_io
    for name in _stage_names():
        stage = model.stages[name]
        ins, _ = stage_io(cfg)[name]
        args = tuple(torch.from_numpy(ref[f"{name}.{n}"].copy()) for n, _, _ in ins)
        assert len(args) == len(example_inputs(cfg, name))
        runs.append((name, lambda stage=stage, args=args: stage(*args)))
    with torch.inference_mode():
        stages = _time_all(runs, repeats)
    return {"engine": "pytorch", "version": torch.__version__, "threads": threads,
            "stages_ms": stages, "max_rss_kib": _max_rss_kib()}


def worker_peak(threads: int, repeats: int) -> dict:
    """GFLOP/s of a PEAK_N^3 f32 matmul through NumPy's BLAS, PyTorch and onnxruntime's MLAS
    (a one-node MatMul graph), best repeat each; the peak is the best of the three."""
    import numpy as np
    import onnxruntime as ort
    import torch
    from onnx import TensorProto, helper
    torch.set_num_threads(threads)
    rng = np.random.default_rng(0)
    a = rng.standard_normal((PEAK_N, PEAK_N), dtype=np.float32)
    b = rng.standard_normal((PEAK_N, PEAK_N), dtype=np.float32)
    ta, tb = torch.from_numpy(a), torch.from_numpy(b)
    shape = [PEAK_N, PEAK_N]
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["a", "b"], ["c"])], "peak",
        [helper.make_tensor_value_info(n, TensorProto.FLOAT, shape) for n in ("a", "b")],
        [helper.make_tensor_value_info("c", TensorProto.FLOAT, shape)])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    sess = ort.InferenceSession(model.SerializeToString(), so, providers=["CPUExecutionProvider"])
    flop = 2.0 * PEAK_N ** 3
    by = {
        "numpy": min(_time(repeats, lambda: a @ b)),
        "pytorch": min(_time(repeats, lambda: torch.mm(ta, tb))),
        "onnxruntime": min(_time(repeats, lambda: sess.run(None, {"a": a, "b": b}))),
    }
    gflops = {k: flop / ms / 1e6 for k, ms in by.items()}
    return {"threads": threads, "n": PEAK_N, "gflops_by_library": gflops,
            "gflops": max(gflops.values())}


def stage_flops(config: str) -> dict[str, int]:
    from .config import get_config
    from .export import example_inputs, set_deterministic
    from .model import build_model
    from .stage_table import _flops
    set_deterministic()
    cfg = get_config(config)
    model = build_model(cfg, 0)
    return {n: _flops(model.stages[n], example_inputs(cfg, n)) for n in _stage_names()}


def _run_json(cmd: list[str], threads: int) -> dict:
    p = subprocess.run(cmd, env=_thread_env(threads), capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stderr}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def _engines(spec: dict) -> tuple[str, ...]:
    """The engines one bundle runs through: the three, ours on its compiled form if any, and
    ours and onnxruntime on its int8 forms if named."""
    return (ENGINES + ((COMPILED,) if spec.get("compiled") is not None else ())
            + (INT8_ENGINES if spec.get("int8") is not None else ()))


def _engine_cmd(engine: str, sim: Path, spec: dict, threads: int, repeats: int) -> list[str]:
    if engine in ("satmap", COMPILED, SATMAP_INT8):
        bundle = {COMPILED: spec["compiled"], "satmap": spec["bundle"],
                  SATMAP_INT8: (spec.get("int8") or {}).get("satmap")}[engine]
        return [str(sim), "bench-stages", "--bundle", str(bundle), "--inputs",
                str(spec["bundle"]), "--threads", str(threads), "--repeats", str(repeats),
                "--calibration", str(MODELS_ROOT / "calibration" / "nuscenes_like.toml")]
    folder = spec["int8"]["ort"] if engine == ORT_INT8 else spec["bundle"]
    worker = "onnxruntime" if engine == ORT_INT8 else engine
    cmd = [sys.executable, "-m", "satmap_ref.peers", "worker", "--engine", worker, "--bundle",
           str(folder), "--config", spec["config"], "--threads", str(threads),
           "--repeats", str(repeats)]
    if spec["weights"] is not None:
        cmd += ["--weights", str(spec["weights"])]
    return cmd


def _median(xs: list[float]) -> float:
    return statistics.median(xs) if xs else float("nan")


def _config_of(bundle: Path) -> str:
    import tomllib
    return tomllib.loads((bundle / "manifest.toml").read_text())["model"]["config"]


def run(sim: Path, specs: list[dict], threads: list[int], rounds: int, repeats: int,
        log=print) -> dict:
    result = {"machine": _machine(), "peak": {}, "bundles": {}}
    for t in threads:
        result["peak"][t] = _run_json([sys.executable, "-m", "satmap_ref.peers", "worker",
                                       "--engine", "peak", "--threads", str(t), "--repeats",
                                       "5"], t)
        log(f"peak at {t} thread(s): {result['peak'][t]['gflops']:.1f} GFLOP/s")
    for spec in specs:
        name = spec["name"]
        entry = {"config": spec["config"], "flops": stage_flops(spec["config"]), "threads": {}}
        for t in threads:
            engines = _engines(spec)
            pooled = {e: {} for e in engines}
            extra = {e: {"max_rss_kib": 0} for e in engines}
            step = []
            for r in range(rounds):
                k = r % len(engines)
                order = engines[k:] + engines[:k]
                for engine in order:
                    out = _run_json(_engine_cmd(engine, sim, spec, t, repeats), t)
                    for stage, ms in out["stages_ms"]:
                        pooled[engine].setdefault(stage, []).extend(ms)
                    extra[engine]["max_rss_kib"] = max(extra[engine]["max_rss_kib"],
                                                       out["max_rss_kib"])
                    for k in ("version", "kernel_family", "step_skipped"):
                        if out.get(k) is not None:
                            extra[engine][k] = out[k]
                    if engine == "satmap":
                        step.extend(out["step_ms"])
                    log(f"{name} threads {t} round {r + 1}/{rounds}: {engine} done")
            entry["threads"][t] = {
                "median_ms": {e: {s: _median(v) for s, v in pooled[e].items()} for e in engines},
                "samples_ms": pooled,
                "satmap_step_median_ms": _median(step) if step else None,
                "engines": extra,
            }
        result["bundles"][name] = entry
    return result


def _machine() -> dict:
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    from .golden import kernel_family
    return {"cpu": model, "cores": os.cpu_count(), "kernel_family": kernel_family(),
            "python": platform.python_version()}


def _parse_int8(spec: str) -> tuple[str, dict]:
    """`NAME=W8A8.satmap:ORT_INT8_DIR`: a bundle's int8 forms (ours compiled and calibrated,
    onnxruntime's from `satmap_ref.ort_int8`)."""
    name, rest = spec.split("=", 1)
    ours, _, ort = rest.partition(":")
    if not ort:
        raise ValueError(f"--int8 {spec}: want NAME=W8A8.satmap:ORT_INT8_DIR")
    return name, {"satmap": Path(ours).resolve(), "ort": Path(ort).resolve()}


def _parse_bundle(spec: str) -> dict:
    name, rest = spec.split("=", 1)
    bundle, _, weights = rest.partition(":")
    bundle_path = Path(bundle).resolve()
    config = _config_of(bundle_path)
    w = Path(weights).resolve() if weights else DEFAULT_WEIGHTS.get(config)
    compiled = bundle_path.with_name(bundle_path.name + ".satmap")
    return {"name": name, "bundle": bundle_path, "config": config, "weights": w,
            "compiled": compiled if compiled.is_file() else None, "int8": None}


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "worker":
        ap = argparse.ArgumentParser(prog="satmap_ref.peers worker")
        ap.add_argument("--engine", required=True, choices=("onnxruntime", "pytorch", "peak"))
        ap.add_argument("--bundle", type=Path)
        ap.add_argument("--config")
        ap.add_argument("--weights", type=Path)
        ap.add_argument("--threads", type=int, required=True)
        ap.add_argument("--repeats", type=int, required=True)
        a = ap.parse_args(argv[1:])
        if a.engine == "onnxruntime":
            out = worker_onnxruntime(a.bundle, a.threads, a.repeats)
        elif a.engine == "pytorch":
            out = worker_pytorch(a.bundle, a.config, a.weights, a.threads, a.repeats)
        else:
            out = worker_peak(a.threads, a.repeats)
        print(json.dumps(out))
        return
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sim", type=Path, help="the satmap-sim binary")
    ap.add_argument("--render", type=Path,
                    help="only rewrite <out>.md from this JSON of an earlier run")
    ap.add_argument("--bundle", action="append", default=[],
                    help="NAME=DIR[:WEIGHTS] of an exported folder bundle (repeatable)")
    ap.add_argument("--int8", action="append", default=[],
                    help="NAME=W8A8.satmap:ORT_INT8_DIR: a bundle's int8 forms, timed beside it "
                         "(repeatable)")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per stage per process")
    ap.add_argument("--out", type=Path, required=True, help="path stem: writes .md and .json")
    a = ap.parse_args(argv)
    if a.render is not None:
        result = json.loads(a.render.read_text())
        write_markdown(a.out.with_suffix(".md"), markdown(result, result["command"]))
        return
    if a.sim is None or not a.bundle:
        ap.error("--sim and at least one --bundle are required")
    specs = [_parse_bundle(s) for s in a.bundle]
    int8 = dict(_parse_int8(s) for s in a.int8)
    for spec in specs:
        spec["int8"] = int8.pop(spec["name"], None)
    if int8:
        ap.error(f"--int8 for bundles not given: {', '.join(int8)}")
    result = run(a.sim.resolve(), specs, a.threads, a.rounds, a.repeats,
                 log=lambda s: print(s, file=sys.stderr, flush=True))
    command = "python -m satmap_ref.peers " + " ".join(argv)
    result["command"] = command
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
    write_markdown(a.out.with_suffix(".md"), markdown(result, command))
    print(f"wrote {a.out.with_suffix('.md')} and {a.out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
