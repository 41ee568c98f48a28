import h5py, numpy as np
def frames(path):
    f=h5py.File(path,'r'); t=f['eit/t'][:]; V=f['eit/v'][:]
    tt=f['truth/t'][:]; cols=[f['truth/'+k][:,0] for k in ('x_mm','y_mm','diameter_mm','force_n')]
    T=1/1.3; ref=V[t<4.0].mean(0); S={}
    def at(x):
        i=np.searchsorted(tt,x,side='right')-1; return tuple(round(c[i],1) for c in cols)
    for k in range(len(t)):
        a=at(t[k]-T/2+1e-6); b=at(t[k]+T/2-1e-6)
        if np.isfinite(a[3]) and a==b: S[a]=V[k]-ref
    return S,ref
S,ref=frames('size-info-off.h5'); sig=2e-4*np.abs(ref)
print("25 mm press vs the closest 15 mm press at the same place or up to 3-4 mm away (any force 1-10 N, any scale): chi in noise units, one frame")
for x0,y0 in [(0,0),(0,-18),(-36,0),(-36,-36)]:
    out=[]
    for F in (2.0,6.0,10.0):
        y=S[(x0,y0,25.0,F)]/sig; best=(np.inf,None)
        best0=np.inf
        for (x,yy,d,F2),v in S.items():
            if d!=15.0 or abs(x-x0)>3.5 or abs(yy-y0)>3.5: continue
            xv=v/sig; s=(xv@y)/(xv@xv); c=np.linalg.norm(y-s*xv)
            if c<best[0]: best=(c,(x-x0,yy-y0,F2))
            if x==x0 and yy==y0: best0=min(best0,c)
        out.append(f"{F:.0f} N: same place {best0:.1f}, shifted {best[0]:.1f} (at offset {best[1][0]:+.0f},{best[1][1]:+.0f} mm, {best[1][2]:.0f} N)")
    print(f"  ({x0},{y0}): "+"; ".join(out))
