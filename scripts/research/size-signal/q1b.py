import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
print("=== mean area_mm2 [and sd over the 9 locations] per diameter and force, hold means; seeds 1/2/3 ===")
for s in [1,2,3]:
    D=load(f'{ROOT}/base-s{s}/cd.csv')
    d=D['true_diameter_mm']; F=D['true_force_n']
    print(f"seed {s}: " + "  ".join(f"F={f:.0f}" for f in [2,4,6,8,10]))
    for dd in [10,20,25]:
        cells=[]
        for f in [2,4,6,8,10]:
            m=(d==dd)&(F==f)
            # hold means per location
            locs=set(zip(D['true_x_mm'][m],D['true_y_mm'][m]))
            hm=[D['area_mm2'][m&(D['true_x_mm']==x)&(D['true_y_mm']==y)].mean() for x,y in locs]
            cells.append(f"{np.mean(hm):4.0f}±{np.std(hm):3.0f}")
        print(f"  {dd} mm  "+"  ".join(cells))
print("=== area ratio 25/10 per location (mean over forces) and per force (mean over locations), seed 1 ===")
for s in [1,2,3]:
    D=load(f'{ROOT}/base-s{s}/cd.csv')
    d=D['true_diameter_mm']; F=D['true_force_n']; X=D['true_x_mm']; Y=D['true_y_mm']
    R=np.full((9,5),np.nan); locs=sorted(set(zip(X,Y)))
    for i,(x,y) in enumerate(locs):
        for j,f in enumerate([2,4,6,8,10]):
            m=(X==x)&(Y==y)&(F==f)
            a=D['area_mm2'][m&(d==25)]; b=D['area_mm2'][m&(d==10)]
            if len(a) and len(b): R[i,j]=a.mean()/b.mean()
    print(f"seed {s} per loc:", " ".join(f"({x:.0f},{y:.0f}):{v:.2f}" for (x,y),v in zip(locs,np.nanmean(R,1))))
    print(f"        per force:", np.round(np.nanmean(R,0),2), " within-location sd over forces:", np.round(np.nanmean(np.nanstd(R,1)),3), " between-location sd:", np.round(np.nanstd(np.nanmean(R,1)),3))
