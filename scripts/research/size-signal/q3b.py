import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from q3 import *
def lc(x,y):
    ax,ay=abs(x)>20,abs(y)>20
    return 'corner' if ax and ay else ('edge' if ax or ay else 'centre')
F5=['area_mm2','c_sum','peak','r2_all_mm2','a25_mm2']
for s in (1,2,3):
    cal=Cal(f'{ROOT}/base-s{s}/calib-two-sizes.toml')
    Cr=load(f'{ROOT}/base-s{s}/cal2-2s.csv'); C=holds(sub(Cr,ok(Cr)))
    T=load(f'{ROOT}/base-s{s}/cd-2s.csv'); T=sub(T,ok(T))
    cls=np.array([lc(a,b) for a,b in zip(T['true_x_mm'],T['true_y_mm'])])
    sm=SizeModel(C,F5); dh=sm(T)
    line=[]
    for name,feats in [('none',None),('oracle','oracle'),('dhat5',F5)]:
        m=fit_model(cal,C,feats,'quad'); e=m(T,cal.f_rows(T))-T['true_force_n']
        line.append(name+": "+" ".join(f"{c}(10/20/25) "+"/".join(f"{np.sqrt(np.mean(e[(cls==c)&(T['true_diameter_mm']==d)]**2)):.2f}" for d in (10,20,25)) for c in ('corner','edge','centre')))
    print(f"seed {s} d-hat (in-sample size model) mean by class: "+"; ".join(f"{c}: "+"/".join(f"{dh[(cls==c)&(T['true_diameter_mm']==d)].mean():.1f}" for d in (10,20,25)) for c in ('corner','edge','centre')))
    for l in line: print("   ",l)
