import csv, numpy as np
def load(path, matched=True):
    rows=[]
    with open(path) as f:
        r=csv.DictReader(f)
        for row in r:
            if matched and row['kind']!='matched': continue
            rows.append(row)
    cols=rows[0].keys()
    out={}
    for c in cols:
        try: out[c]=np.array([float(r[c]) if r[c]!='' else np.nan for r in rows])
        except ValueError: out[c]=np.array([r[c] for r in rows])
    return out
