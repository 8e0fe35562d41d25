"""Relative mAP of each quarter of each render (by position in the render) of the pickled sets. Output: analyze2.txt."""
import pickle
import sys

import numpy as np

for f in sys.argv[1:]:
    p = pickle.load(open(f, "rb"))
    C, H = p["clear"], p["mats"][0]
    G = C.n_groups
    keys = list(dict.fromkeys(p["groups"]))
    print(f, G)
    # by quarter of position in render (per folder)
    folders = sorted({k[0] for k in keys})
    for fo in folders:
        idx = [i for i, k in enumerate(keys) if k[0] == fo]
        for q, part in enumerate(np.array_split(idx, 4)):
            w = np.zeros(G)
            w[part] = 1
            print("  ", fo[-8:], "quarter", q, f"rel {H.map50(w) / C.map50(w):.3f} clear {C.map50(w):.3f}")
        w = np.zeros(G)
        w[idx] = 1
        print("  ", fo[-8:], f"all rel {H.map50(w) / C.map50(w):.3f} clear {C.map50(w):.3f}")
