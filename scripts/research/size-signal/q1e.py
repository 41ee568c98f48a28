import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
exec(open('q1d.py').read().split('print("Q1 (b)')[0])
NAMES=['area_mm2','c_sum','peak','C/peak','a50_mm2','a25_mm2','r2_50_mm2','r2_all_mm2','dp_kpa']
def cls5(x,y):
    ax,ay=abs(x)>30,abs(y)>30
    return 'corner' if ax and ay else ('edge' if ax or ay else 'inner')
print("Calibration two sizes: log(feature at 22 mm) - log(feature at 15 mm), same location and force (hold means), mean ± sd over holds; seeds 1-3 pooled")
print("location classes on the 5x5 grid: corner = (±40,±40), edge = other points on the outer ring, inner = the 3x3 inner points")
res={}
for s in [1,2,3]:
    C=load(f'{ROOT}/base-s{s}/cal2.csv'); C=sub(C,ok(C))
    key=np.array([f"{a:.0f},{b:.0f},{c:.2f}" for a,b,c in zip(C['true_x_mm'],C['true_y_mm'],C['true_force_n'])])
    for k in np.unique(key):
        m=key==k; d=C['true_diameter_mm'][m]
        if not ((d==15).any() and (d==22).any()): continue
        x,y=C['true_x_mm'][m][0],C['true_y_mm'][m][0]
        for n in NAMES:
            v=np.log(C['c_sum']/C['peak'])[m] if n=='C/peak' else np.log(C[n][m])
            res.setdefault((n,cls5(x,y)),[]).append(v[d==22].mean()-v[d==15].mean())
print(f"{'feature':11s}"+"".join(f"{c:>18s}" for c in ['corner','edge','inner']))
for n in NAMES:
    print(f"{n:11s}"+"".join(f"{np.mean(res[(n,c)]):8.3f}±{np.std(res[(n,c)]):.3f}    " for c in ['corner','edge','inner']))
print("  (log(22/15) = 0.383: a feature proportional to d would move 0.383; z = mean/sd per press)")
