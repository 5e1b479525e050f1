import sys,json
for l in open(sys.argv[1] if len(sys.argv)>1 else 'run_all.log'):
    try: r=json.loads(l)
    except: continue
    f=lambda v: [float('%.3g'%x) for x in v] if isinstance(v,list) else v
    print(f"{r['stage']:18} {r['variant']:16} ok={r['ok']!s:5} ms={r.get('median_ms',-1):8.2f} err={f(r.get('maxabs','-'))} refmax={f(r.get('refmax','-'))} ort_err={f(r.get('ort_maxabs_vs_f32','-'))} t_vs_ort={f(r.get('tract_vs_ort','-'))} {r.get('err','')[:150]} {r.get('ort_err','')[:80]}")
