# Bench every quantized variant in tract (subprocess per model), compare to tract f32 outputs and to ORT on the same quantized model.
import subprocess, sys, json, glob, os, numpy as np, onnxruntime as ort
D = 'docs/int8_probe/'
inp = np.load(D + 'inputs.npz')
pat = sys.argv[1] if len(sys.argv) > 1 else '*'
env = dict(os.environ)
extra = sys.argv[2] if len(sys.argv) > 2 else ''
if extra: 
    k, v = extra.split('='); env[k] = v
rows = []
for p in sorted(glob.glob(D + f'q/{pat}.onnx')):
    b = os.path.basename(p)[:-5]
    if b.endswith('__gemm2mm'): continue
    st, var = b.split('__')
    tag = b + ('__' + extra.replace('=', '') if extra else '')
    out = D + f'res/{tag}.npz'
    try:
        r = subprocess.run([sys.executable, D + 'tbench.py', p, st, out, '15', '--profile'], capture_output=True, text=True, timeout=600, env=env)
        ok = r.returncode == 0
        info = json.loads(r.stdout.strip().splitlines()[-1]) if ok else {'err': ' | '.join(l for l in r.stderr.strip().splitlines() if 'rror' in l or 'Caused' in l or l.startswith('    '))[:600] or r.stderr[-300:]}
    except subprocess.TimeoutExpired:
        ok = False; info = {'err': 'timeout'}
    row = {'stage': st, 'variant': var, 'ok': ok, **info}
    ref = np.load(D + f'res/{st}_f32.npz')
    if ok:
        q = np.load(out)
        row['maxabs'] = [float(np.abs(q[k] - ref[k]).max()) for k in ref.files]
        row['refmax'] = [float(np.abs(ref[k]).max()) for k in ref.files]
    try:
        so = ort.SessionOptions(); so.intra_op_num_threads = 1; so.inter_op_num_threads = 1
        s = ort.InferenceSession(p, so, providers=['CPUExecutionProvider'])
        feeds = {i.name: inp[f'eval/{st}/{i.name}'] for i in s.get_inputs()}
        o = s.run(None, feeds)
        row['ort_maxabs_vs_f32'] = [float(np.abs(o[i] - ref[k]).max()) for i, k in enumerate(ref.files)]
        if ok: row['tract_vs_ort'] = [float(np.abs(o[i] - q[k]).max()) for i, k in enumerate(ref.files)]
    except Exception as e:
        row['ort_err'] = str(e)[:200]
    print(json.dumps(row), flush=True)
