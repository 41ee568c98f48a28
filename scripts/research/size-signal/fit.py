import os, sys, tomllib, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
from q2 import ok, sub, holds, logfield
GF=0.05
class Cal:
    def __init__(s,path):
        c=tomllib.load(open(path,'rb')); s.c=c; r=c['region']
        s.r=(r['x_min_mm'],r['x_max_mm'],r['y_min_mm'],r['y_max_mm'])
        la=c['pneumatic']['locaware']; s.la=la; m=la['map']
        s.q=(m['quadratic']['a0'],m['quadratic']['a1'],m['quadratic']['a2']); s.lo=m['signal_min']; s.hi=m['signal_max']
        s.g=np.array(la['gain']); s.b=np.array(la['offset'])
    def phi(s,x,y):
        x0,x1,y0,y1=s.r
        u=np.clip(2*(x-x0)/(x1-x0)-1,-1,1); v=np.clip(2*(y-y0)/(y1-y0)-1,-1,1)
        return np.stack([np.ones_like(u),u,v,u*u,u*v,v*v],1)
    def inside(s,p):
        a0,a1,a2=s.q; at=lambda t: a0+a1*t+a2*t*t
        vert=-a1/(2*a2) if a2!=0 else np.inf
        pe=np.where((a2<0)&(vert<p),max(vert,s.lo),p)
        return np.maximum(at(pe),at(s.lo))
    def slope(s,p):
        a0,a1,a2=s.q
        return np.where(s.inside(p)>a0+a1*p+a2*p*p,0.0,np.maximum(a1+2*a2*p,0))
    def f(s,p):
        p=np.asarray(p,float)
        return np.where(p>s.hi,s.inside(s.hi)+s.slope(s.hi)*(p-s.hi),np.where(p<s.lo,s.inside(s.lo)+s.slope(s.lo)*(p-s.lo),s.inside(p)))
    def f_rows(s,D):
        # single contacts: f(dP); several: backed out of the locaware force
        P=s.phi(D['x_mm'],D['y_mm']); g=np.maximum(P@s.g,GF); b=P@s.b
        fb=(D['pneumatic-locaware_n']-b)/g
        return np.where(D['truth_contacts']<=1, s.f(D['dp_kpa']), fb)
def fit_fields(P,f,y,Z,lg,lb,la):
    n=P.shape[1]; X=np.column_stack([P*f[:,None],P]+([Z] if Z is not None else []))
    p=X.shape[1]; prior=np.zeros(p); prior[0]=1
    pen=np.r_[np.full(n,lg),np.full(n,lb),np.full(p-2*n,la)]
    w=np.linalg.solve(X.T@X+np.diag(pen),X.T@y+pen*prior)
    return w
def predict(w,P,f,Z):
    n=P.shape[1]; g=np.maximum(P@w[:n],GF); F=g*f+P@w[n:2*n]
    if Z is not None: F=F+Z@w[2*n:]
    return np.maximum(F,0)
