import os, sys, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
ROOT = os.environ.get('SIZE_RESEARCH_DIR', '/tmp/size-research')
from load import load
for s in [1,2,3]:
  for suf in ['','-2s']:
    T=load(f'{ROOT}/base-s{s}/cd{suf}.csv'); M=load(f'{ROOT}/base-s{s}/mc{suf}.csv')
    out=[]
    for strat in ['pneumatic-locaware_n','pneumatic-area-aware_n','pneumatic-forward_n']:
        e=T[strat]-T['true_force_n']; em=M[strat]-M['true_force_n']
        per=[np.sqrt(np.mean(e[T['true_diameter_mm']==d]**2)) for d in [10,20,25]]
        out.append(f"{strat[:-2]}: {np.sqrt(np.mean(e**2)):.3f} ({per[0]:.2f}/{per[1]:.2f}/{per[2]:.2f}) mc {np.sqrt(np.mean(em**2)):.3f}")
    print(s,suf or '-1s', ' | '.join(out))
