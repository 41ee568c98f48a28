import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
from q2 import ok, sub, holds, logfield, sizefit
from fit import Cal, fit_fields, predict
LAG=np.r_[1e-4*np.sqrt(10)**np.arange(17)]  # relative grid as in the Rust default
def sizeterms(form,z,f):
    if form=='lin': return np.column_stack([z*f,z])       # shipped area-aware form
    if form=='quad': return np.column_stack([z*f*f])      # saturation: dF ~ dkappa F^2
    if form=='lin+quad': return np.column_stack([z*f,z,z*f*f])
def run(seed,zspec,form,clamp=True,one_size=False):
    cal=Cal(f'{ROOT}/base-s{seed}/calib{"" if one_size else "-two-sizes"}.toml')
    suf='' if one_size else '-2s'
    Cr=load(f'{ROOT}/base-s{seed}/{"cal" if one_size else "cal2"}{suf}.csv'); C=holds(sub(Cr,ok(Cr)))
    T=load(f'{ROOT}/base-s{seed}/cd{suf}.csv'); T=sub(T,ok(T))
    M=load(f'{ROOT}/base-s{seed}/mc{suf}.csv'); M=sub(M,ok(M))
    la=cal.la; lg,lb=la['lambda_g'],la['lambda_b']
    fC=cal.f(C['dp_kpa']); PC=cal.phi(C['x_mm'],C['y_mm']); y=C['true_force_n']
    if zspec is None:
        zf=None
    elif zspec=='oracle':
        zf=lambda D: D['true_diameter_mm']/15-1
    elif zspec=='area-global':
        ref=C['area_mm2'].mean(); zf=lambda D: D['area_mm2']/ref-1
    elif zspec.startswith('ref:'):
        zf=logfield(C,zspec[4:])
    elif zspec.startswith('dhat:'):
        sf=sizefit(C,zspec[5:].split('+')); zf=lambda D: sf(D)/15-1
    if zf is None:
        w=fit_fields(PC,fC,y,None,lg,lb,0); Z=lambda D,f: None
    else:
        zc=zf(C); lo,hi=zc.min(),zc.max()
        zz=(lambda D: np.clip(zf(D),lo,hi)) if clamp else zf
        Z=lambda D,f: sizeterms(form,zz(D),f)
        grp=np.array([f"{a:.0f},{b:.0f}" for a,b in zip(C['true_x_mm'],C['true_y_mm'])])
        best=None
        for rel in LAG:
            e=0
            for gi,g in enumerate(np.unique(grp)):
                tr=grp!=g
                w=fit_fields(PC[tr],fC[tr],y[tr],Z(C,fC)[tr],lg,lb,rel*tr.sum())
                e+=((predict(w,PC[~tr],fC[~tr],Z(C,fC)[~tr])-y[~tr])**2).sum()
            if best is None or e<best[0]: best=(e,rel)
        w=fit_fields(PC,fC,y,Z(C,fC),lg,lb,best[1]*len(y))
    out=[]
    for D in (T,M):
        fD=cal.f_rows(D); P=cal.phi(D['x_mm'],D['y_mm'])
        out.append(predict(w,P,fD,Z(D,fD))-D['true_force_n'])
    eT,eM=out; rm=lambda e: np.sqrt(np.mean(e**2))
    return (rm(eT),*[rm(eT[T['true_diameter_mm']==d]) for d in (10,20,25)],rm(eM)),w
def table(cases,one_size=False):
    for name,zs,form,clamp in cases:
        rs=[run(s,zs,form,clamp,one_size) for s in (1,2,3)]
        print(f"{name:44s} "+" | ".join(f"{a:.3f} ({b:.2f}/{c:.2f}/{d:.2f}) mc {m:.3f}" for (a,b,c,d,m),_ in rs),"  w_size(s1):",np.round(rs[0][1][12:],3))
if __name__=='__main__':
    print("Two-size calibration (15+22 mm); fields refitted in Python with the calibration's own f and (lambda_g, lambda_b); size-term ridge weight by leave-one-location-out CV")
    print("cross-diameter RMSE (10/20/25 mm) and multi-contact per-contact RMSE; seeds 1 | 2 | 3")
    table([("locaware (python refit, no size term)",None,None,True),
           ("oracle z=d/15-1, lin form, clamped",'oracle','lin',True),
           ("oracle z=d/15-1, quad form, clamped",'oracle','quad',True),
           ("oracle z=d/15-1, lin form, extrapolated",'oracle','lin',False),
           ("oracle z=d/15-1, quad form, extrapolated",'oracle','quad',False),
           ("area/global-1, lin (shipped form)",'area-global','lin',True),
           ("area/global-1, quad",'area-global','quad',True),
           ("log area - ref(x,y,dP), lin",'ref:area_mm2','lin',True),
           ("log area - ref(x,y,dP), quad",'ref:area_mm2','quad',True),
           ("log r2_all - ref(x,y,dP), quad",'ref:r2_all_mm2','quad',True),
           ("dhat(area,C,peak), quad",'dhat:area_mm2+c_sum+peak','quad',True),
           ("dhat(r2_all,a25,area), quad",'dhat:r2_all_mm2+a25_mm2+area_mm2','quad',True),
           ])
