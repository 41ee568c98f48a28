import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from template import *
def fit_multi(dv,pts,iters=3,win=4.0):
    """backfitting: each contact's (d, place) fitted with the others' fitted templates subtracted; amplitudes jointly by LS"""
    K=len(pts); offs=np.arange(-win,win+0.01,STEP)
    cur=[(list(DS).index(16.0),gidx(x,y)) for x,y in pts]
    def amps(cur):
        T=np.stack([BANK[i,p] for i,p in cur],1); a=np.linalg.lstsq(T,dv,rcond=None)[0]; return T,a
    dh=[np.nan]*K
    for _ in range(iters):
        for j,(x,y) in enumerate(pts):
            T,a=amps(cur); other=T@a-T[:,j]*a[j]; r=dv-other
            idx=np.unique([gidx(x+u,y+v) for u in offs for v in offs])
            B=BANK[:,idx,:]; tv=B@r; tt=np.einsum('dpm,dpm->dp',B,B); res=r@r-tv**2/tt
            k=np.unravel_index(np.argmin(res),res.shape); cur[j]=(k[0],idx[k[1]])
            curve=res[:,k[1]]; i=k[0]
            if 0<i<len(DS)-1:
                aa,bb,cc=curve[i-1],curve[i],curve[i+1]; den=aa-2*bb+cc; off=0.5*(aa-cc)/den if den>0 else 0
                dh[j]=DS[i]+off*(DS[1]-DS[0])
            else: dh[j]=DS[i]
    return dh
def dhat_any(csvpath,h5path):
    D=load(csvpath); t,V,ref=rec_frames(h5path)
    out=np.full(len(D['t_s']),np.nan)
    det=np.isfinite(D['x_mm'])
    for ts in np.unique(D['t_s']):
        rows=np.where((D['t_s']==ts)&det)[0]
        if len(rows)==0: continue
        k=np.argmin(np.abs(t-ts)); dv=(V[k]-ref)/ref
        pts=[(D['x_mm'][r],D['y_mm'][r]) for r in rows]
        if len(rows)==1: out[rows[0]]=fit_frame(dv,*pts[0])[0]
        else:
            for r,d in zip(rows,fit_multi(dv,pts)): out[r]=d
    return out
if __name__=='__main__':
    for s in (1,2,3):
        for name,h5 in (('cd-2s','cross-diameter'),('mc-2s','multi-contact'),('cal2-2s','calibration-two-sizes')):
            dh=dhat_any(f'{ROOT}/base-s{s}/{name}.csv',f'{ROOT}/base-s{s}/{h5}.h5')
            np.save(f'{ROOT}/base-s{s}/{name}_dhat_tpl.npy',dh)
            D=load(f'{ROOT}/base-s{s}/{name}.csv'); m=D['kind']=='matched'
            print(s,name,"mean d-hat per true d:"," ".join(f"{d:.0f}:{np.nanmean(dh[m&(D['true_diameter_mm']==d)]):.1f}±{np.nanstd(dh[m&(D['true_diameter_mm']==d)]):.1f}" for d in np.unique(D['true_diameter_mm'][m])),flush=True)
