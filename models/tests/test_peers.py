"""`satmap_ref.peers` (make bench-peers) without running any engine: its table arithmetic, the
marker block it rewrites in docs/perf.md, the stage order it reads off a bundle, and the
resident-set reading each worker reports."""

from pathlib import Path

from satmap_ref import peers

BUNDLE = Path(__file__).resolve().parents[1] / "bundles" / "test"


def _result() -> dict:
    stages = peers._stage_names(BUNDLE)
    med = {e: {s: 10.0 * (i + 1) for s in stages} for i, e in enumerate(peers.ENGINES)}
    return {
        "machine": {"cpu": "x", "cores": 2, "kernel_family": "amd-avx512f"},
        "peak": {"1": {"gflops": 100.0, "gflops_by_library": {"numpy": 100.0}, "n": 2048}},
        "bundles": {"test": {"config": "test", "flops": {s: 1e9 for s in stages},
                             "threads": {"1": {"median_ms": med, "satmap_step_median_ms": 70.0,
                                               "engines": {e: {"max_rss_kib": 2048}
                                                           for e in peers.ENGINES}}}}},
    }


def test_stage_order_comes_from_the_manifest_without_torch():
    assert peers._stage_names(BUNDLE) == ("image_encoder", "bev_query", "bev_encoder",
                                          "satellite_encoder", "map_decoder")


def test_table_ratios_and_peak_share():
    md = peers.markdown(_result(), "cmd")
    # ours 10 ms, onnxruntime 20 ms, pytorch 30 ms: x ORT 0.50; 1 GFLOP in 10 ms = 100 GFLOP/s.
    assert "| bev_query | 1.000 | 10.00 | 20.00 | 30.00 | 0.50 | 0.33 | 100% / 50% / 33% |" in md
    # A frame is six image encoders and the other four stages once.
    assert "| frame: 6 x image_encoder + the rest | | 100.0 | 200.0 | 300.0 | 0.50 | 0.33 | |" in md
    assert "2 / 2 / 2" in md


def test_the_block_is_replaced_between_markers_and_the_rest_kept(tmp_path):
    doc = tmp_path / "perf.md"
    doc.write_text(f"# Title\nhand text\n{peers.BEGIN}\nold table\n{peers.END}\ntail text\n")
    peers.write_markdown(doc, "new table\n")
    text = doc.read_text()
    assert "old table" not in text and "new table" in text
    assert text.startswith("# Title\nhand text\n") and text.endswith("tail text\n")


def test_max_rss_is_this_process_high_water_mark():
    kib = peers._max_rss_kib()
    status = Path("/proc/self/status").read_text()
    rss = int(next(ln for ln in status.splitlines() if ln.startswith("VmRSS:")).split()[1])
    assert kib >= rss > 0


def test_the_compiled_form_gets_its_own_columns_where_it_was_timed():
    result = _result()
    run = result["bundles"]["test"]["threads"]["1"]
    run["median_ms"][peers.COMPILED] = {s: 5.0 for s in peers._stage_names(BUNDLE)}
    run["engines"][peers.COMPILED] = {"max_rss_kib": 1024}
    md = peers.markdown(result, "cmd")
    assert "| ours compiled ms | compiled x ORT |" in md
    # 5 ms against onnxruntime's 20: 0.25; the frame 6 x 5 + 4 x 5 = 50 against 200.
    assert "| bev_query | 1.000 | 10.00 | 20.00 | 30.00 | 0.50 | 0.33 | 5.00 | 0.25 | " in md
    assert "| 100.0 | 200.0 | 300.0 | 0.50 | 0.33 | 50.0 | 0.25 | |" in md
    assert "Ours on the compiled form: 1 MiB." in md


def test_a_bundle_with_a_compiled_sibling_runs_it_too():
    spec = peers._parse_bundle(f"test={BUNDLE}")
    assert spec["compiled"] == BUNDLE.with_name("test.satmap")
    assert peers._engines(spec) == peers.ENGINES + (peers.COMPILED,)
    cmd = peers._engine_cmd(peers.COMPILED, Path("sim"), spec, 1, 3)
    assert cmd[:4] == ["sim", "bench-stages", "--bundle", str(BUNDLE.with_name("test.satmap"))]


def test_every_stage_runs_once_before_any_is_timed():
    calls = []
    runs = [(name, lambda name=name: calls.append(name)) for name in ("a", "b", "c")]
    timed = peers._time_all(runs, repeats=2)
    # One settling pass over all, then each stage's warm-up run and its two timed runs.
    assert calls == ["a", "b", "c"] + ["a"] * 3 + ["b"] * 3 + ["c"] * 3
    assert [name for name, _ in timed] == ["a", "b", "c"]
    assert all(len(ms) == 2 and all(t >= 0.0 for t in ms) for _, ms in timed)


def test_the_int8_forms_get_a_table_of_their_own_where_they_were_timed():
    result = _result()
    run = result["bundles"]["test"]["threads"]["1"]
    stages = peers._stage_names(BUNDLE)
    run["median_ms"][peers.SATMAP_INT8] = {s: 8.0 for s in stages}
    run["median_ms"][peers.ORT_INT8] = {s: 40.0 for s in stages}
    md = peers.markdown(result, "cmd")
    # Ours f32 (the folder's, no compiled form here) 10 ms, int8 8; ORT f32 20, int8 40.
    assert "#### test, 1 thread(s): int8" in md
    assert "| bev_query | 10.00 | 8.00 | 20.00 | 40.00 | 0.80 | 0.20 |" in md
    assert "| frame: 6 x image_encoder + the rest | 100.0 | 80.0 | 200.0 | 400.0 | 0.80 | 0.20 |" in md
    # Without int8 timings, no int8 table.
    assert "int8" not in peers.markdown(_result(), "cmd")


def test_int8_forms_are_named_per_bundle():
    name, forms = peers._parse_int8("test=bundles/test-w8a8.satmap:build/test-ort-int8")
    assert name == "test" and forms["satmap"].name == "test-w8a8.satmap"
    assert forms["ort"].name == "test-ort-int8"
    spec = {"bundle": BUNDLE, "config": "test", "weights": None, "compiled": None, "int8": forms}
    assert peers._engines(spec)[-2:] == peers.INT8_ENGINES
    cmd = peers._engine_cmd(peers.SATMAP_INT8, Path("sim"), spec, 1, 3)
    assert cmd[cmd.index("--bundle") + 1].endswith("test-w8a8.satmap")
    assert cmd[cmd.index("--inputs") + 1] == str(BUNDLE)
    ort = peers._engine_cmd(peers.ORT_INT8, Path("sim"), spec, 1, 3)
    assert ort[ort.index("--engine") + 1] == "onnxruntime"
    assert ort[ort.index("--bundle") + 1].endswith("test-ort-int8")
