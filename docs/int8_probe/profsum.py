import json, sys, collections
p = json.load(open(sys.argv[1])); n = int(sys.argv[2]) if len(sys.argv) > 2 else 12
nodes = [x for x in p['nodes'] if x.get('secs_per_iter')]
tot = sum(x['secs_per_iter'] for x in nodes)
by = collections.Counter()
for x in nodes: by[x['op_name']] += x['secs_per_iter']
print(f"total {tot*1e3:.2f} ms; by op:", ', '.join(f"{k}={v*1e3:.2f}" for k, v in by.most_common(n)))
for x in sorted(nodes, key=lambda x: -x['secs_per_iter'])[:n]:
    print(f"  {x['secs_per_iter']*1e3:7.3f} {x['op_name']:<28} {x['node_name'][:80]} {x.get('cost','')}")
