import os, sys, numpy as np, h5py
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
J=np.fromfile(f'{ROOT}/info/jac_120x4187.f64').reshape(4187,120)   # rows: elements
CEN=np.fromfile(f'{ROOT}/info/centroids_4187.f64').reshape(4187,2)
SIG=3.0; DS=np.arange(6,38,2.0); STEP=2.0; GX=np.arange(-48,48.01,STEP)
def radial(d,r):
    R=d/2; rho=np.linspace(0,R,200)[None,:]; r=r[:,None]
    w=(rho/SIG**2)*np.exp(-(r**2+rho**2)/(2*SIG**2))*np.i0(r*rho/SIG**2)
    return np.trapezoid(w,rho,axis=1)
BANKF=f'{ROOT}/info/bank.npy'
if os.path.exists(BANKF): BANK=np.load(BANKF)
else:
    P=np.array([(x,y) for y in GX for x in GX])
    rr=np.linspace(0,80,801); BANK=np.zeros((len(DS),len(P),120))
    for i,d in enumerate(DS):
        prof=radial(d,rr)
        for k in range(0,len(P),300):
            dist=np.linalg.norm(CEN[None,:,:]-P[k:k+300,None,:],axis=2)
            X=-np.interp(dist,rr,prof)
            BANK[i,k:k+300]=X@J
    np.save(BANKF,BANK)
NG=len(GX)
def gidx(x,y):
    ix=np.clip(np.round((x+48)/STEP).astype(int),0,NG-1); iy=np.clip(np.round((y+48)/STEP).astype(int),0,NG-1); return iy*NG+ix
def fit_frame(dv,x,y,win=4.0):
    best=(np.inf,None)
    offs=np.arange(-win,win+0.01,STEP)
    idx=np.unique([gidx(x+a,y+b) for a in offs for b in offs])
    T=BANK[:,idx,:]                       # (nd, npos, 120)
    tv=T@dv; tt=np.einsum('dpm,dpm->dp',T,T)
    res=dv@dv-tv**2/tt                    # (nd, npos)
    k=np.unravel_index(np.argmin(res),res.shape); p=k[1]
    curve=res[:,p]; i=k[0]
    if 0<i<len(DS)-1:
        a,b,c=curve[i-1],curve[i],curve[i+1]; den=a-2*b+c
        off=0.5*(a-c)/den if den>0 else 0
        dh=DS[i]+off*(DS[1]-DS[0])
    else: dh=DS[i]
    return dh, res.min()/(dv@dv)
def rec_frames(h5path):
    f=h5py.File(h5path,'r'); t=f['eit/t'][:]; V=f['eit/v'][:]
    tt=f['truth/t'][:]; F=f['truth/force_n'][:]
    first=tt[np.isfinite(F).any(1)][0]
    ref=V[(t+0.5/1.3)<first][-10:].mean(0)
    return t,V,ref
def dhat_csv(csvpath,h5path,rows_mask=None):
    D=load(csvpath); t,V,ref=rec_frames(h5path)
    out=np.full(len(D['t_s']),np.nan); fr=np.full(len(D['t_s']),np.nan)
    for i,(ts,x,y,n) in enumerate(zip(D['t_s'],D['x_mm'],D['y_mm'],D['truth_contacts'])):
        if not np.isfinite(x) or n!=1: continue
        k=np.argmin(np.abs(t-ts)); dv=(V[k]-ref)/ref
        out[i],fr[i]=fit_frame(dv,x,y)
    D['dhat_tpl']=out; D['tpl_res']=fr
    return D
if __name__=='__main__':
    def lc(x,y):
        ax,ay=abs(x)>20,abs(y)>20
        return 'corner' if ax and ay else ('edge' if ax or ay else 'centre')
    for s in (1,2,3):
        D=dhat_csv(f'{ROOT}/base-s{s}/cd.csv',f'{ROOT}/base-s{s}/cross-diameter.h5')
        m=D['kind']=='matched'; cls=np.array([lc(a,b) for a,b in zip(D['true_x_mm'],D['true_y_mm'])])
        print(f"seed {s} template d-hat, cross-diameter test, mean±sd per true d: "+"; ".join(f"{c}: "+" ".join(f"{d}:{np.nanmean(D['dhat_tpl'][m&(cls==c)&(D['true_diameter_mm']==d)]):.1f}±{np.nanstd(D['dhat_tpl'][m&(cls==c)&(D['true_diameter_mm']==d)]):.1f}" for d in (10,20,25)) for c in ('corner','edge','centre')), " rel.resid", np.round(np.nanmean(D['tpl_res'][m]),3))
        np.save(f'{ROOT}/base-s{s}/cd_dhat_tpl.npy',D['dhat_tpl'])
