import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
import q2b
from q2b import run
for lab,grid in (("CV-chosen weight",q2b.LAG),("no shrinkage (rel 1e-8)",np.array([1e-8]))):
    q2b.LAG=grid
    r=[run(s,'area-global','lin',True) for s in (1,2,3)]
    print(f"shipped form, area/global-1, two sizes, {lab:24s}: "+" | ".join(f"{a:.3f} ({b:.2f}/{c:.2f}/{d:.2f}) mc {m:.3f}" for (a,b,c,d,m),_ in r), " k_gain,k_offset s1/s2/s3:", [tuple(np.round(w[12:],3)) for _,w in r])
