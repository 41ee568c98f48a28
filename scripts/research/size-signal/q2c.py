import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
from q2 import ok, sub, holds
print("Variance of a = area/area_ref - 1 over the two-size calibration hold means (sequential sums of squares: location, then force level, then size), seeds 1/2/3")
for s in (1,2,3):
    C=load(f'{ROOT}/base-s{s}/cal2-2s.csv'); C=holds(sub(C,ok(C)))
    a=C['area_mm2']/C['area_mm2'].mean()-1
    loc=np.array([f"{x:.0f},{y:.0f}" for x,y in zip(C['true_x_mm'],C['true_y_mm'])])
    F=np.round(C['true_force_n'],2); d=C['true_diameter_mm']
    def onehot(k): u=np.unique(k); return (k[:,None]==u[None,:]).astype(float)
    tot=((a-a.mean())**2).sum(); prev=0; out=[]
    X=np.ones((len(a),1))
    for name,blk in [('location',onehot(loc)),('force',onehot(F)),('size',onehot(d)),('loc x size',onehot(np.char.add(loc,d.astype(str))))]:
        X=np.column_stack([X,blk]); r=a-X@np.linalg.lstsq(X,a,rcond=None)[0]; ss=tot-(r@r)
        out.append(f"{name} {100*(ss-prev)/tot:4.1f}%"); prev=ss
    out.append(f"residual {100*(tot-prev)/tot:4.1f}%")
    print(f"seed {s}: sd(a)={a.std():.2f}; "+", ".join(out))
    # mean area per force (15 mm)
    m=d==15
    print("   mean area at 15 mm per force level:", " ".join(f"{f:.1f}N:{C['area_mm2'][m&(F==f)].mean():.0f}" for f in np.unique(F)))
