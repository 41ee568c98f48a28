import h5py, numpy as np
f=h5py.File('size-info.h5','r')
t=f['eit/t'][:]; V=f['eit/v'][:]
tt=f['truth/t'][:]; tx=f['truth/x_mm'][:,0]; ty=f['truth/y_mm'][:,0]; tF=f['truth/force_n'][:,0]; td=f['truth/diameter_mm'][:,0]
T=1/1.3
def truth_at(x):
    i=np.searchsorted(tt,x,side='right')-1; return (tx[i],ty[i],tF[i],td[i]) if i>=0 else (np.nan,)*4
ref=V[(t+T/2)<tt[np.isfinite(tF)][0] if np.isfinite(tF).any() else t<4].mean(0)
ref=V[t<4.0].mean(0)
S={}
for k in range(len(t)):
    a=truth_at(t[k]-T/2+1e-6); b=truth_at(t[k]+T/2-1e-6)
    if np.isfinite(a[2]) and a==b:
        S[(round(a[0]),round(a[1]),round(a[3]),round(a[2]))]=V[k]-ref
sig=2e-4*np.abs(ref)  # the paper profile's per-channel noise sd
Ff=np.arange(1,11)
print("Noise-free simulated frames (ideal profile). For a press of diameter d at force F, the closest 10/15 mm press at the same place (any force 1-10 N, any scale factor):")
print("chi = ||dv_d - s*dv_ref(F')|| / noise (paper profile noise 2e-4|v| per channel, one frame); chi >> 1: distinguishable in one frame")
for loc in [(0,0),(0,-18),(-36,0),(-36,-36)]:
    for dref in (10,15):
        row=[]
        for d in (20,25):
            chis=[]
            for F in (2,6,10):
                y=S[(loc[0],loc[1],d,F)]/sig
                best=np.inf
                for F2 in Ff:
                    x=S[(loc[0],loc[1],dref,F2)]/sig; s=(x@y)/(x@x); best=min(best,np.linalg.norm(y-s*x))
                chis.append(best)
            row.append(f"{d} mm vs {dref}: chi at 2/6/10 N = "+"/".join(f"{c:.1f}" for c in chis))
        print(f"loc {loc}: signal |dv|/noise at 6 N, 10 mm: {np.linalg.norm(S[(loc[0],loc[1],10,6)]/sig):.0f};  "+";  ".join(row))
# baseline: same diameter, position 1 mm off? not available; report force-step chi for scale
