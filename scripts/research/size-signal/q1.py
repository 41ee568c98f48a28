import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
np.set_printoptions(precision=3, suppress=True)
def feats(D):
    A=D['area_mm2']; C=D['c_sum']; P=D['peak']; dp=D['dp_kpa']
    return {'area':A,'C':C,'peak':P,'C/area':C/A,'C/peak':C/P,'dP':dp}
print("=== Q1a: per diameter, feature / same (location, force) 10 mm value (cross-diameter test, hold means) ===")
allratio={}
for s in [1,2,3]:
    D=load(f'{ROOT}/base-s{s}/cd.csv')
    F=feats(D)
    key=np.array([f"{a:.0f},{b:.0f},{c:.0f}" for a,b,c in zip(D['true_x_mm'],D['true_y_mm'],D['true_force_n'])])
    d=D['true_diameter_mm']
    for name,v in F.items():
        for dd in [20,25]:
            rs=[]; cvs=[]
            for k in np.unique(key):
                a=v[(key==k)&(d==dd)]; b=v[(key==k)&(d==10)]
                if len(a) and len(b):
                    rs.append(a.mean()/b.mean())
            allratio.setdefault((name,dd),[]).extend(rs)
# within-hold noise (CV of frames in one hold)
for s in [1,2,3]:
    D=load(f'{ROOT}/base-s{s}/cd.csv')
    F=feats(D)
    key=np.array([f"{a:.0f},{b:.0f},{c:.0f},{e:.0f}" for a,b,c,e in zip(D['true_x_mm'],D['true_y_mm'],D['true_force_n'],D['true_diameter_mm'])])
    for name,v in F.items():
        cv=[np.std(v[key==k],ddof=1)/np.mean(v[key==k]) for k in np.unique(key) if (key==k).sum()>1]
        allratio.setdefault((name,'holdcv'),[]).extend(cv)
print(f"{'feature':8s} {'20/10 mean±sd':>16s} {'25/10 mean±sd':>16s}  frac cells 25>10   within-hold CV")
for name in ['area','C','peak','C/area','C/peak','dP']:
    r20=np.array(allratio[(name,20)]); r25=np.array(allratio[(name,25)])
    print(f"{name:8s} {r20.mean():7.3f}±{r20.std():.3f}  {r25.mean():7.3f}±{r25.std():.3f}   {np.mean(r25>1):.2f}   {np.mean(allratio[(name,'holdcv')]):.3f}")
