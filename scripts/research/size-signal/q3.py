import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
from q2 import ok, sub, holds
from fit import Cal, fit_fields, predict
LAG=1e-4*np.sqrt(10)**np.arange(17)
def phi40(x,y):
    u,v=x/40,y/40; return np.stack([np.ones_like(u),u,v,u*u,u*v,v*v],1)
def lname(D): return np.array([f"{a:.0f},{b:.0f}" for a,b in zip(D['true_x_mm'],D['true_y_mm'])])
def folds_of(groups,k):
    u=np.unique(groups); rng=np.random.default_rng(7); perm=rng.permutation(len(u))
    f={g:perm[i]%k for i,g in enumerate(u)}; return np.array([f[g] for g in groups])
class SizeModel:
    """log d = sum_j Phi(x,y) . w_j * r_j, r_j = log feature_j - ref_j(x,y,log dP) (ref fitted by least squares on the calibration)"""
    def __init__(s,C,feats,lam=None):
        s.feats=feats; s.refs=[]
        for f in feats:
            X=np.column_stack([phi40(C['x_mm'],C['y_mm']),np.log(C['dp_kpa'])])
            s.refs.append(np.linalg.lstsq(X,np.log(C[f]),rcond=None)[0])
        X=s.Z(C); y=np.log(C['true_diameter_mm']); s.ym=y.mean()
        if lam is None:
            g=lname(C); best=None
            for l in (1e-4,1e-3,1e-2,1e-1,1):
                e=0
                for u in np.unique(g):
                    tr=g!=u; w=np.linalg.solve(X[tr].T@X[tr]+l*tr.sum()*np.eye(X.shape[1]),X[tr].T@(y[tr]-s.ym)); e+=((X[~tr]@w+s.ym-y[~tr])**2).sum()
                if best is None or e<best[0]: best=(e,l)
            lam=best[1]
        s.lam=lam
        s.w=np.linalg.solve(X.T@X+lam*len(y)*np.eye(X.shape[1]),X.T@(y-s.ym))
    def Z(s,D):
        P=phi40(D['x_mm'],D['y_mm']); cols=[]
        for f,w in zip(s.feats,s.refs):
            r=np.log(D[f])-np.column_stack([P,np.log(D['dp_kpa'])])@w; cols.append(P*r[:,None])
        return np.column_stack(cols)
    def __call__(s,D): return np.exp(s.Z(D)@s.w+s.ym)
def crossfit_dhat(C,feats):
    """out-of-location d-hat for each calibration sample (what the force model then sees has test-like noise)"""
    g=lname(C); out=np.zeros(len(g)); lam=SizeModel(C,feats).lam
    for u in np.unique(g):
        tr=g!=u; out[~tr]=SizeModel(sub(C,tr),feats,lam)(sub(C,~tr))
    return out
def terms(form,z,f):
    if form=='lin': return np.column_stack([z*f,z])
    if form=='quad': return np.column_stack([z*f*f])
def fit_model(cal,C,feats,form,crossfit=True):
    """returns predictor(D, f) -> force; fields + size terms, size ridge weight by 5-fold location CV"""
    fC=cal.f(C['dp_kpa']); PC=cal.phi(C['x_mm'],C['y_mm']); y=C['true_force_n']
    lg,lb=cal.la['lambda_g'],cal.la['lambda_b']
    if feats is None:
        w=fit_fields(PC,fC,y,None,lg,lb,0); return lambda D,f: predict(w,cal.phi(D['x_mm'],D['y_mm']),f,None)
    if feats=='oracle':
        zc=C['true_diameter_mm']/15-1; zfun=lambda D: D['true_diameter_mm']/15-1
    else:
        sm=SizeModel(C,feats); dh=crossfit_dhat(C,feats) if crossfit else sm(C)
        zc=dh/15-1; zfun=lambda D: sm(D)/15-1
    lo,hi=np.quantile(zc,[0.0,1.0])
    ZC=terms(form,np.clip(zc,lo,hi),fC)
    fo=folds_of(lname(C),5); best=None
    for rel in LAG:
        e=0
        for k in range(5):
            tr=fo!=k; w=fit_fields(PC[tr],fC[tr],y[tr],ZC[tr],lg,lb,rel*tr.sum())
            e+=((predict(w,PC[~tr],fC[~tr],ZC[~tr])-y[~tr])**2).sum()
        if best is None or e<best[0]: best=(e,rel)
    w=fit_fields(PC,fC,y,ZC,lg,lb,best[1]*len(y))
    return lambda D,f: predict(w,cal.phi(D['x_mm'],D['y_mm']),f,terms(form,np.clip(zfun(D),lo,hi),f))
def calib_cv(cal,C,feats,form):
    """location-held-out RMSE on the calibration (5 folds; everything refitted per fold)"""
    fo=folds_of(lname(C),5); e=np.zeros(len(fo))
    for k in range(5):
        tr=fo!=k; m=fit_model(cal,sub(C,tr),feats,form); Dt=sub(C,~tr)
        e[~tr]=m(Dt,cal.f(Dt['dp_kpa']))-Dt['true_force_n']
    return np.sqrt(np.mean(e**2))
def test(cal,C,feats,form,T,M):
    m=fit_model(cal,C,feats,form); rm=lambda e: np.sqrt(np.mean(e**2))
    eT=m(T,cal.f_rows(T))-T['true_force_n']; eM=m(M,cal.f_rows(M))-M['true_force_n']
    return (rm(eT),*[rm(eT[T['true_diameter_mm']==d]) for d in (10,20,25)],rm(eM))
if __name__=='__main__':
    CANDS=[('none',None,None),('oracle d, lin','oracle','lin'),('oracle d, quad','oracle','quad'),
           ('dhat[area,C,peak], lin',['area_mm2','c_sum','peak'],'lin'),('dhat[area,C,peak], quad',['area_mm2','c_sum','peak'],'quad'),
           ('dhat[area,C,peak,r2_all,a25], lin',['area_mm2','c_sum','peak','r2_all_mm2','a25_mm2'],'lin'),
           ('dhat[area,C,peak,r2_all,a25], quad',['area_mm2','c_sum','peak','r2_all_mm2','a25_mm2'],'quad')]
    which=sys.argv[1] if len(sys.argv)>1 else 'both'
    for s in (1,2,3):
        cal=Cal(f'{ROOT}/base-s{s}/calib-two-sizes.toml')
        Cr=load(f'{ROOT}/base-s{s}/cal2-2s.csv'); C=holds(sub(Cr,ok(Cr)))
        T=load(f'{ROOT}/base-s{s}/cd-2s.csv'); T=sub(T,ok(T)); M=load(f'{ROOT}/base-s{s}/mc-2s.csv'); M=sub(M,ok(M))
        print(f"seed {s}:  candidate | calibration location-held-out RMSE (15+22 mm) | test: cross-diameter (10/20/25) | multi-contact")
        for name,feats,form in CANDS:
            cv=calib_cv(cal,C,feats,form)
            a,b,c,d,mc=test(cal,C,feats,form,T,M)
            print(f"   {name:38s} cal-CV {cv:.3f} | cd {a:.3f} ({b:.2f}/{c:.2f}/{d:.2f}) | mc {mc:.3f}",flush=True)
