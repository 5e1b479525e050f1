# Build calibration / eval inputs per stage from golden frames. Run with models/.venv python.
import numpy as np
from safetensors.numpy import load_file
G='models/golden/test/'
f0=load_file(G+'frame_000.safetensors'); f1=load_file(G+'frame_001.safetensors')
ref=load_file('models/bundles/test/reference.safetensors')
rng=np.random.default_rng(0)
out={}
# eval inputs (one frame): reference.safetensors
ev={'image_encoder':{'image':ref['image_encoder.image'],'camera_index':ref['image_encoder.camera_index']},
    'bev_query':{'can_bus':ref['bev_query.can_bus']},
    'bev_encoder':{'bev_query':ref['bev_encoder.bev_query'],'gathered':ref['bev_encoder.gathered']},
    'satellite_encoder':{'satellite':ref['satellite_encoder.satellite']},
    'map_decoder':{'camera_bev':ref['map_decoder.camera_bev'],'satellite_bev':ref['map_decoder.satellite_bev']}}
cal={k:[] for k in ev}
for f in (f0,f1):
    for c in range(6):
        cal['image_encoder'].append({'image':f['images'][c],'camera_index':np.array([c],np.int64)})
    cal['bev_query'].append({'can_bus':f['can_bus']})
    cal['bev_encoder'].append({'bev_query':f['bev_query'],'gathered':f['gathered']})
    cal['satellite_encoder'].append({'satellite':f['satellite']})
    cal['map_decoder'].append({'camera_bev':f['camera_bev'],'satellite_bev':f['satellite_bev']})
# perturbed copies
for k in list(cal):
    base=list(cal[k])
    for b in base:
        for j in range(2):
            d={}
            for n,v in b.items():
                if v.dtype==np.uint8: d[n]=np.clip(v.astype(np.int16)+rng.integers(-12,13,v.shape),0,255).astype(np.uint8)
                elif v.dtype==np.float32: d[n]=(v*(1+0.05*rng.standard_normal(v.shape))+0.02*v.std()*rng.standard_normal(v.shape)).astype(np.float32)
                else: d[n]=v
            cal[k].append(d)
flat={}
for k,v in ev.items():
    for n,a in v.items(): flat[f'eval/{k}/{n}']=a
for k,lst in cal.items():
    for i,d in enumerate(lst):
        for n,a in d.items(): flat[f'cal/{k}/{i}/{n}']=a
np.savez('inputs.npz',**flat)
print({k:len(v) for k,v in cal.items()})
