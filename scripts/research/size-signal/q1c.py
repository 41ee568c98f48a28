import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
FEATS=['area_mm2','c_sum','peak','a50_mm2','a25_mm2','r2_50_mm2','r2_all_mm2','dp_kpa']
def lf(D,name):
    if name=='C/area': return np.log(D['c_sum']/D['area_mm2'])
    if name=='C/peak': return np.log(D['c_sum']/D['peak'])
    return np.log(D[name])
NAMES=['area_mm2','c_sum','peak','C/peak','a50_mm2','a25_mm2','r2_50_mm2','r2_all_mm2','dp_kpa']
def loc_class(x,y):
    ax,ay=abs(x)>20,abs(y)>20
    return 'corner' if ax and ay else ('edge' if ax or ay else 'centre')
print("Q1: log(feature) elasticity wrt log(diameter) on the cross-diameter test, hold means,")
print("fixed effects per (seed, location, force); slope and residual sd per location class; 'res' = resid sd/slope = diameter resolution in log units (0.69 = factor 2)")
rows=[]
for s in [1,2,3]:
    D=load(f'{ROOT}/base-s{s}/cd.csv')
    key=np.array([f"{a:.0f},{b:.0f},{c:.0f},{e:.0f}" for a,b,c,e in zip(D['true_x_mm'],D['true_y_mm'],D['true_force_n'],D['true_diameter_mm'])])
    for k in np.unique(key):
        m=key==k
        r={'seed':s,'x':D['true_x_mm'][m][0],'y':D['true_y_mm'][m][0],'F':D['true_force_n'][m][0],'d':D['true_diameter_mm'][m][0]}
        for n in NAMES: r[n]=lf(D,n)[m].mean()
        rows.append(r)
H={k:np.array([r[k] for r in rows]) for k in rows[0]}
cls=np.array([loc_class(x,y) for x,y in zip(H['x'],H['y'])])
cell=np.array([f"{a},{b},{c},{e}" for a,b,c,e in zip(H['seed'],H['x'],H['y'],H['F'])])
print(f"{'feature':11s}" + "".join(f"{c:>26s}" for c in ['corner','edge','centre','all']))
for n in NAMES:
    out=[]
    for c in ['corner','edge','centre','all']:
        m = (cls==c) if c!='all' else np.ones(len(cls),bool)
        y=H[n][m]; ld=np.log(H['d'][m]); cc=cell[m]
        # demean within cell
        yc=y.copy(); lc=ld.copy()
        for u in np.unique(cc):
            k=cc==u; yc[k]-=y[k].mean(); lc[k]-=ld[k].mean()
        b=(yc@lc)/(lc@lc); res=yc-b*lc
        ncell=len(np.unique(cc)); dof=len(y)-ncell-1
        sd=np.sqrt(res@res/dof)
        out.append(f"b={b:5.2f} sd={sd:.3f} res={sd/abs(b):5.2f}")
    print(f"{n:11s}"+"".join(f"{o:>26s}" for o in out))
