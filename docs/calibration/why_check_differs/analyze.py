"""Bootstrap over episodes and over frames of two pickled sets (diag.py), and random splits of their pooled
episodes into halves: is the difference between the sets what the bootstrap allows? Output: analyze.txt."""
import pickle
import sys

import numpy as np

from weather_gym.lab.calibration.frame_ap import frame_matches

fs = sys.argv[1:]
P = [pickle.load(open(f, "rb")) for f in fs]
def boot(clear, hit, rng, B=400):
    n = clear.n_groups
    w = rng.multinomial(n, np.full(n, 1 / n), size=B).astype(float)
    c = clear.map50_many(w)
    return np.std(hit.map50_many(w) / c, ddof=1)
rng = np.random.default_rng(0)
for f, p in zip(fs, P):
    gts, d, cd, mbh = p["gts"], p["dets"][0], p["cd"], p["mbh"]
    n = len(gts)
    ep_c, ep_h = p["clear"], p["mats"][0]
    fr_c = frame_matches(gts, cd, groups=list(range(n)), min_box_height=mbh)
    fr_h = frame_matches(gts, d, groups=list(range(n)), min_box_height=mbh)
    print(f, "rel %.4f" % (ep_h.map50() / ep_c.map50()), f"se episodes {boot(ep_c, ep_h, rng):.4f}",
          f"se frames {boot(fr_c, fr_h, rng):.4f}")
    # first-frame-of-episode only vs all
    firsts = [i for i in range(n) if i == 0 or p["groups"][i] != p["groups"][i - 1]]
# pooled permutation: halves of episodes
gts = P[0]["gts"] + P[1]["gts"]
groups = [("a",) + tuple([g]) for g in P[0]["groups"]] + [("b",) + tuple([g]) for g in P[1]["groups"]]
cd = P[0]["cd"] + P[1]["cd"]
dd = P[0]["dets"][0] + P[1]["dets"][0]
C = frame_matches(gts, cd, groups=groups, min_box_height=P[0]["mbh"])
H = frame_matches(gts, dd, groups=groups, min_box_height=P[0]["mbh"])
G = C.n_groups
na = P[0]["clear"].n_groups
w = np.zeros(G)
w[:na] = 1
obs = H.map50(w) / C.map50(w) - H.map50(1 - w) / C.map50(1 - w)
diffs = []
for _ in range(300):
    perm = rng.permutation(G)
    w = np.zeros(G)
    w[perm[:na]] = 1
    diffs.append(H.map50(w) / C.map50(w) - H.map50(1 - w) / C.map50(1 - w))
diffs = np.array(diffs)
print("pooled rel %.4f" % (H.map50() / C.map50()), f"observed ref-check diff {obs:.4f}", f"random-split diff sd {diffs.std():.4f}",
      "-> se per 320-frame set %.4f" % (diffs.std() / np.sqrt(2)), f"p(|d|>=obs) {np.mean(np.abs(diffs) >= abs(obs)):.3f}")
