# Interleaved timing: tbench_multi.py stage nrounds model.onnx... (first = f32 reference)
# Loads every model in tract (onnx -> into_model -> into_runnable = declutter+optimize), warms up,
# then runs them round-robin so machine-load drift hits all variants equally. Prints JSON rows.
import sys, time, json, numpy as np, tract, os
stage, nr, paths = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
inp = np.load('docs/int8_probe/inputs.npz')
R = {}
for p in paths:
    try:
        if p.endswith('.tar'):
            m = tract.nnef().load(p); order = [m.input_name(i) for i in range(m.input_count())]
        else:
            im = tract.onnx().load(p); order = [im.input_name(i) for i in range(im.input_count())]
            m = im.into_model()
        r = m.into_runnable()
        xs = [inp[f'eval/{stage}/{n}'] for n in order]
        outs = [o.to_numpy() for o in r.run(xs)]
        for _ in range(2): r.run(xs)
        R[p] = dict(r=r, xs=xs, outs=outs, ts=[])
    except Exception as e:
        print(json.dumps({'stage': stage, 'model': os.path.basename(p), 'ok': False, 'err': str(e).split('\n')[0][:300]}), flush=True)
for _ in range(nr):
    for p, d in R.items():
        t = time.perf_counter(); d['r'].run(d['xs']); d['ts'].append(time.perf_counter() - t)
ref = R.get(paths[0])
for p, d in R.items():
    row = {'stage': stage, 'model': os.path.basename(p), 'ok': True, 'median_ms': 1e3 * float(np.median(d['ts'])),
           'min_ms': 1e3 * float(np.min(d['ts']))}
    if ref:
        row['ratio_vs_f32'] = row['median_ms'] / (1e3 * float(np.median(ref['ts'])))
        row['maxabs'] = [float(np.abs(a - b).max()) for a, b in zip(d['outs'], ref['outs'])]
    print(json.dumps(row), flush=True)
