# NNEF round trip: onnx -> tract typed (into_model = typed+decluttered) -> write tar (tract_core ext, no onnx ext)
# -> read back with tract.nnef() (core registry only) -> run, compare to the ONNX-loaded run.
import sys, os, re, json, tarfile, numpy as np, tract, glob
D = 'docs/int8_probe/'
inp = np.load(D + 'inputs.npz')
paths = sys.argv[1:] or sorted(p for p in glob.glob(D + 'q/*.onnx') if 'gemm2mm' not in p and 'qop_u8_pc_gemm' not in p)
for p in paths:
    b = os.path.basename(p)[:-5]; st = b.split('__')[0] if '__' in b else b
    tar = D + f'nnef/{b}.nnef.tar'
    row = {'model': b}
    try:
        im = tract.onnx().load(p); order = [im.input_name(i) for i in range(im.input_count())]
        xs = [inp[f'eval/{st}/{n}'] for n in order]
        m = im.into_model()
        tract.nnef().write_model_to_tar(m, tar)
        ref = [o.to_numpy() for o in m.into_runnable().run(xs)]
        with tarfile.open(tar) as t:
            g = t.extractfile('graph.nnef').read().decode()
        frags = sorted(set(re.findall(r'^\s*\w+\s*=\s*(tract_[a-z0-9_]+)\s*\(', g, re.M) + re.findall(r'\b(tract_[a-z_]+_[a-z0-9_]+)\s*\(', g)))
        row['tract_ops'] = [f for f in frags if not f.startswith('tract_core')] + [f for f in frags if f.startswith('tract_core')]
        row['exts'] = re.findall(r'^extension\s+(.*);', g, re.M)
        row['qdt'] = sorted(set(re.findall(r'(?:i8|u8|scalar)\s*\[?[^\n]{0,0}', '')))
        m2 = tract.nnef().load(tar)
        o2 = [o.to_numpy() for o in m2.into_runnable().run(xs)]
        row['reload_ok'] = True
        row['maxdiff_vs_onnx_load'] = [float(np.abs(a.astype(np.float64) - b2.astype(np.float64)).max()) for a, b2 in zip(ref, o2)]
    except Exception as e:
        es = str(e); import re as _r; mm = _r.search(r"No serializer found for node #\d+ \"[^\"]*\" (\S+)", es); row["err"] = ("no NNEF serializer for " + mm.group(1)) if mm else es.split("\n")[0][:300]
    print(json.dumps(row), flush=True)
