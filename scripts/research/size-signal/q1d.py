import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
def loc_class(x,y):
    ax,ay=abs(x)>20,abs(y)>20
    return 'corner' if ax and ay else ('edge' if ax or ay else 'centre')
def phi(x,y):
    u,v=x/40,y/40
    return np.stack([np.ones_like(u),u,v,u*u,u*v,v*v],1)
SETS={'area':['area_mm2'],'area+C+peak+dP':['area_mm2','c_sum','peak','dp_kpa'],
      'shape(a25,r2all,r2_50,C/peak)':['a25_mm2','r2_all_mm2','r2_50_mm2','C/peak'],
      'all':['area_mm2','c_sum','peak','dp_kpa','a25_mm2','a50_mm2','r2_all_mm2','r2_50_mm2']}
def X_of(D,feats,loc='poly'):
    cols=[]
    for f in feats:
        v=np.log(D['c_sum']/D['peak']) if f=='C/peak' else np.log(D[f])
        cols.append(v)
    Z=np.stack([np.ones(len(cols[0]))]+cols,1)
    P=phi(D['x_mm'],D['y_mm'])  # EIT centroid, as a calibration would see it
    return np.einsum('ni,nj->nij',Z,P).reshape(len(Z),-1)
def ridge(X,y,lam):
    mu=X.mean(0); sd=X.std(0); keep=sd>1e-12
    X=X[:,keep]; mu=mu[keep]; sd=sd[keep]; ym=y.mean()
    Xs=(X-mu)/sd
    A=Xs.T@Xs+lam*len(y)*np.eye(X.shape[1])
    w=np.linalg.solve(A,Xs.T@(y-ym))
    return lambda Xn: ((Xn[:,keep]-mu)/sd)@w+ym
def ok(D):
    m=D['kind']=='matched'
    for f in ['area_mm2','c_sum','peak','dp_kpa','a25_mm2','a50_mm2','r2_all_mm2','r2_50_mm2']:
        m&=np.isfinite(D[f])&(D[f]>0)
    return m
def sub(D,m): return {k:v[m] for k,v in D.items()}
def cv_lambda(X,y,groups,grid=(1e-4,1e-3,1e-2,1e-1,1)):
    best=None
    for lam in grid:
        e=0
        for g in np.unique(groups):
            tr=groups!=g; f=ridge(X[tr],y[tr],lam); e+=((f(X[~tr])-y[~tr])**2).sum()
        if best is None or e<best[0]: best=(e,lam)
    return best[1]
print("Q1 (b): log d regressed on log features x quadratic location field, trained on the 15+22 mm calibration (hold frames, settled),")
print("lambda by leave-one-location-out CV on the calibration; predicted diameter on the cross-diameter test, mean ± sd per true diameter and location class")
for name,feats in SETS.items():
    print(f"-- features: {name}")
    acc={}
    for s in [1,2,3]:
        C=load(f'{ROOT}/base-s{s}/cal2.csv'); C=sub(C,ok(C))
        T=load(f'{ROOT}/base-s{s}/cd.csv'); T=sub(T,ok(T))
        Xc=X_of(C,feats); yc=np.log(C['true_diameter_mm'])
        grp=np.array([f"{a:.0f},{b:.0f}" for a,b in zip(C['true_x_mm'],C['true_y_mm'])])
        lam=cv_lambda(Xc,yc,grp)
        f=ridge(Xc,yc,lam); pd=np.exp(f(X_of(T,feats)))
        cls=np.array([loc_class(x,y) for x,y in zip(T['true_x_mm'],T['true_y_mm'])])
        for d in [10,20,25]:
            for c in ['corner','edge','centre']:
                acc.setdefault((d,c),[]).extend(pd[(T['true_diameter_mm']==d)&(cls==c)])
        # calibration fit quality (in-sample by lolo)
    for c in ['corner','edge','centre']:
        print(f"   {c:7s} "+"  ".join(f"{d}mm: {np.mean(acc[(d,c)]):5.1f}±{np.std(acc[(d,c)]):4.1f}" for d in [10,20,25]))
