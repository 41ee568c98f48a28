import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from q3 import *
def loadx(s,name):
    D=load(f'{ROOT}/base-s{s}/{name}.csv')
    D['dhat_tpl']=np.clip(np.load(f'{ROOT}/base-s{s}/{name}_dhat_tpl.npy'),6,36)
    return D
def ok2(D):
    m=ok(D)&np.isfinite(D['dhat_tpl']); return m
def holds_last(D):
    """hold means, but dhat_tpl from the hold's last frame (noise as in a single test frame)"""
    key=np.array([f"{a:.0f},{b:.0f},{c:.3f},{e:.0f}" for a,b,c,e in zip(D['true_x_mm'],D['true_y_mm'],D['true_force_n'],D['true_diameter_mm'])])
    H=holds(D); ks=np.unique(key)
    H['dhat_tpl']=np.array([D['dhat_tpl'][key==u][-1] for u in ks]); return H
CANDS=[('none',None),('oracle','oracle'),('image[area,C,peak,r2_all,a25]',['area_mm2','c_sum','peak','r2_all_mm2','a25_mm2']),
       ('template d-hat',['dhat_tpl']),('template d-hat + image',['dhat_tpl','area_mm2','c_sum','peak','r2_all_mm2','a25_mm2'])]
if __name__=='__main__':
    form=sys.argv[1] if len(sys.argv)>1 else 'quad'
    print(f"form {form}; size model and size-term weight fitted on the 15+22 mm calibration only (cross-fitted d-hat, location CV)")
    for s in (1,2,3):
        cal=Cal(f'{ROOT}/base-s{s}/calib-two-sizes.toml')
        Cr=loadx(s,'cal2-2s'); C=holds_last(sub(Cr,ok2(Cr)))
        T=loadx(s,'cd-2s'); T=sub(T,ok(T)&(T['kind']=='matched')); M=loadx(s,'mc-2s'); M=sub(M,ok(M)&(M['kind']=='matched'))
        # rows without a template estimate (none expected for matched) keep a neutral value
        for D in (T,M): D['dhat_tpl']=np.where(np.isfinite(D['dhat_tpl']),D['dhat_tpl'],18.5)
        print(f"seed {s}")
        for name,feats in CANDS:
            cv=calib_cv(cal,C,feats,form); a,b,c,d,mc=test(cal,C,feats,form,T,M)
            print(f"   {name:32s} cal-CV {cv:.3f} | cd {a:.3f} ({b:.2f}/{c:.2f}/{d:.2f}) | mc {mc:.3f}",flush=True)
