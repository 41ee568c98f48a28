import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
exec(open('q1d.py').read().split('print("Q1 (b)')[0])
def X_onehot(D,feats,locs):
    cols=[]
    for f in feats:
        cols.append(np.log(D['c_sum']/D['peak']) if f=='C/peak' else np.log(D[f]))
    Z=np.stack([np.ones(len(cols[0]))]+cols,1)
    L=np.stack([(np.abs(D['true_x_mm']-x)<1)&(np.abs(D['true_y_mm']-y)<1) for x,y in locs],1).astype(float)
    return np.einsum('ni,nj->nij',Z,L).reshape(len(Z),-1)
SETS['dP only']=['dp_kpa']
print("3-class accuracy (10/20/25 mm) per frame on the cross-diameter test; ridge on log d, nearest class; chance 0.33")
print("LOHO: leave one press (hold) out, location fixed effects (the location seen with other presses/diameters) = best case 'at a given location'")
print("LOLO: leave one location out, quadratic location field")
print(f"{'features':32s} {'LOHO corner/edge/centre/all':>30s}   {'LOLO all':>8s}")
for name,feats in SETS.items():
    accs={'corner':[],'edge':[],'centre':[]}; lolo=[]
    for s in [1,2,3]:
        T=load(f'{ROOT}/base-s{s}/cd.csv'); T=sub(T,ok(T))
        y=np.log(T['true_diameter_mm']); locs=sorted(set(zip(T['true_x_mm'],T['true_y_mm'])))
        hold=np.array([f"{a:.0f},{b:.0f},{c:.0f},{e:.0f}" for a,b,c,e in zip(T['true_x_mm'],T['true_y_mm'],T['true_force_n'],T['true_diameter_mm'])])
        X=X_onehot(T,feats,locs)
        lam=1e-3
        pred=np.zeros(len(y))
        for h in np.unique(hold):
            tr=hold!=h; pred[~tr]=ridge(X[tr],y[tr],lam)(X[~tr])
        c=np.array([10,20,25])[np.argmin(np.abs(np.exp(pred)[:,None]-np.array([10,20,25])[None,:]),1)]
        cl=np.array([loc_class(a,b) for a,b in zip(T['true_x_mm'],T['true_y_mm'])])
        for k in accs: accs[k].extend(c[cl==k]==T['true_diameter_mm'][cl==k])
        Xp=X_of(T,feats); grp=np.array([f"{a:.0f},{b:.0f}" for a,b in zip(T['true_x_mm'],T['true_y_mm'])])
        for g in np.unique(grp):
            tr=grp!=g; p=np.exp(ridge(Xp[tr],y[tr],1e-2)(Xp[~tr]))
            c=np.array([10,20,25])[np.argmin(np.abs(p[:,None]-np.array([10,20,25])[None,:]),1)]
            lolo.extend(c==T['true_diameter_mm'][~tr])
    allv=sum((accs[k] for k in accs),[])
    print(f"{name:32s} {np.mean(accs['corner']):.2f}/{np.mean(accs['edge']):.2f}/{np.mean(accs['centre']):.2f}/{np.mean(allv):.2f}            {np.mean(lolo):.2f}")
