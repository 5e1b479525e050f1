# Usage: tbench.py model.onnx|model.nnef.tar stage out.npz [nrun] [--profile] [--nnef-core]
import sys, time, json, numpy as np, tract, os
p, stage, outp = sys.argv[1:4]
nrun = int(sys.argv[4]) if len(sys.argv) > 4 and sys.argv[4].isdigit() else 15
inp = np.load('docs/int8_probe/inputs.npz')
names = [k.split('/')[-1] for k in inp.files if k.startswith(f'eval/{stage}/')]
t0 = time.time()
if p.endswith('.tar') or p.endswith('.nnef') or p.endswith('.tgz'):
    model = tract.nnef().load(p)       # core registry only (no with_onnx)
    order = [model.input_name(i) for i in range(model.input_count())]
else:
    im = tract.onnx().load(p)
    order = [im.input_name(i) for i in range(im.input_count())]
    model = im.into_model()
run = model.into_runnable()
tload = time.time() - t0
xs = [inp[f'eval/{stage}/{n}'] for n in order]
outs = [o.to_numpy() for o in run.run(xs)]
for _ in range(3): run.run(xs)
ts = []
for _ in range(nrun):
    t = time.perf_counter(); run.run(xs); ts.append(time.perf_counter() - t)
res = {'median_ms': 1000*float(np.median(ts)), 'min_ms': 1000*float(np.min(ts)), 'load_s': tload}
np.savez(outp, *outs)
if '--profile' in sys.argv:
    prof = json.loads(run.profile_json(xs))
    res['profile'] = prof
    json.dump(prof, open(outp.replace('.npz', '.prof.json'), 'w'))
print(json.dumps({k: v for k, v in res.items() if k != 'profile'}))
