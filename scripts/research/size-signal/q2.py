import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
def phi(x,y):
    u,v=x/40,y/40
    return np.stack([np.ones_like(u),u,v,u*u,u*v,v*v],1)
def ok(D):
    m=D['kind']=='matched'
    for f in ['area_mm2','c_sum','peak','dp_kpa','r2_all_mm2','a25_mm2']:
        m&=np.isfinite(D[f])&(D[f]>0)
    return m
def sub(D,m): return {k:v[m] for k,v in D.items()}
def holds(D):
    key=np.array([f"{a:.0f},{b:.0f},{c:.3f},{e:.0f}" for a,b,c,e in zip(D['true_x_mm'],D['true_y_mm'],D['true_force_n'],D['true_diameter_mm'])])
    out={}
    ks=np.unique(key)
    for k,v in D.items():
        if v.dtype.kind=='f': out[k]=np.array([v[key==u].mean() for u in ks])
    return out
def ridge(X,y,lam):
    # no intercept: all designs are multiplicative corrections
    A=X.T@X+lam*len(y)*np.eye(X.shape[1]); w=np.linalg.solve(A,X.T@y); return w
def cv_fit(X,y,grp,grid=(1e-6,1e-5,1e-4,1e-3,1e-2,1e-1,1.0)):
    best=None
    for lam in grid:
        e=0
        for g in np.unique(grp):
            tr=grp!=g; w=ridge(X[tr],y[tr],lam); e+=((X[~tr]@w-y[~tr])**2).sum()
        if best is None or e<best[0]: best=(e,lam)
    return ridge(X,y,best[1]),best[1]
def logfield(C,feat):
    # reference of log(feature) at a place: quadratic field in the EIT centroid + log dP term, fitted on the calibration
    X=np.column_stack([phi(C['x_mm'],C['y_mm']),np.log(C['dp_kpa'])])
    w=np.linalg.lstsq(X,np.log(C[feat]),rcond=None)[0]
    return lambda D: np.log(D[feat])-np.column_stack([phi(D['x_mm'],D['y_mm']),np.log(D['dp_kpa'])])@w
def sizefit(C,feats):
    # log d regressed on location-referenced log features, location-varying slopes (quadratic field), least squares
    refs=[logfield(C,f) for f in feats]
    def Z(D): 
        P=phi(D['x_mm'],D['y_mm']); return np.column_stack([P*r(D)[:,None] for r in refs])
    X=Z(C); y=np.log(C['true_diameter_mm']); ym=y.mean()
    grp=np.array([f"{a:.0f},{b:.0f}" for a,b in zip(C['true_x_mm'],C['true_y_mm'])])
    w,lam=cv_fit(X,y-ym,grp)
    return lambda D: np.exp(Z(D)@w+ym)
FL='pneumatic-locaware_n'
def designs(D,z,form):
    f=D[FL]
    if form=='lin': return np.column_stack([z*f,z])
    if form=='quad': return np.column_stack([z*f*f])
    if form=='lin+quad': return np.column_stack([z*f,z,z*f*f])
def run(zname,form,seeds=(1,2,3),verbose=False):
    res=[]
    for s in seeds:
        C=holds(sub(load(f'{ROOT}/base-s{s}/cal2-2s.csv'),ok(load(f'{ROOT}/base-s{s}/cal2-2s.csv'))))
        T=load(f'{ROOT}/base-s{s}/cd-2s.csv'); T=sub(T,ok(T))
        M=load(f'{ROOT}/base-s{s}/mc-2s.csv'); M=sub(M,ok(M))
        if zname=='oracle d/15-1': zf=lambda D: D['true_diameter_mm']/15-1
        elif zname=='oracle sim max(0,(d/15)^1.5-1)': zf=lambda D: np.maximum(0,(D['true_diameter_mm']/15)**1.5-1)
        elif zname=='area/global-1 (shipped)':
            ref=C['area_mm2'].mean(); zf=lambda D,ref=ref: D['area_mm2']/ref-1
        elif zname.startswith('log feat/ref(x,y)'):
            feat=zname.split(':')[1]; zf=logfield(C,feat)
        elif zname.startswith('dhat'):
            feats=zname.split(':')[1].split('+'); sf=sizefit(C,feats); zf=lambda D,sf=sf: sf(D)/15-1
        grp=np.array([f"{a:.0f},{b:.0f}" for a,b in zip(C['true_x_mm'],C['true_y_mm'])])
        X=designs(C,zf(C),form); y=C['true_force_n']-C[FL]
        w,lam=cv_fit(X,y,grp)
        pt=T[FL]+designs(T,zf(T),form)@w; pm=M[FL]+designs(M,zf(M),form)@w
        e=pt-T['true_force_n']
        res.append((np.sqrt(np.mean(e**2)),*[np.sqrt(np.mean(e[T['true_diameter_mm']==d]**2)) for d in [10,20,25]],np.sqrt(np.mean((pm-M['true_force_n'])**2)),w,lam))
    return res
if __name__=='__main__':
    print("Residual models on top of the two-size Pneumatic-LocAware (fitted on the 15+22 mm calibration hold means, ridge by leave-one-location-out CV);")
    print("cross-diameter RMSE (10/20/25 mm) and multi-contact per-contact RMSE on the same test recordings, seeds 1 / 2 / 3")
    Z=['none','oracle d/15-1','oracle sim max(0,(d/15)^1.5-1)','area/global-1 (shipped)','log feat/ref(x,y):area_mm2','log feat/ref(x,y):r2_all_mm2','dhat:area_mm2','dhat:r2_all_mm2+a25_mm2+area_mm2']
    for zn in Z:
        for form in (['lin'] if zn=='none' else ['lin','quad']):
            if zn=='none':
                r=[]
                for s in (1,2,3):
                    T=load(f'{ROOT}/base-s{s}/cd-2s.csv'); T=sub(T,ok(T)); M=load(f'{ROOT}/base-s{s}/mc-2s.csv'); M=sub(M,ok(M))
                    e=T[FL]-T['true_force_n']; r.append((np.sqrt(np.mean(e**2)),*[np.sqrt(np.mean(e[T['true_diameter_mm']==d]**2)) for d in [10,20,25]],np.sqrt(np.mean((M[FL]-M['true_force_n'])**2)),None,None))
            else: r=run(zn,form)
            print(f"{zn:38s} {form:5s} " + " | ".join(f"{a:.3f} ({b:.2f}/{c:.2f}/{d:.2f}) mc {m:.3f}" for a,b,c,d,m,_,_ in r), "  w:", np.round(r[0][5],3) if r[0][5] is not None else "")
