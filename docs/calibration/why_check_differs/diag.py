"""Relative mAP of one preset's effect at given k on rendered sets (``A+B`` joins folders, ``:N`` keeps the first N
frames), W weather seeds, with the episode bootstrap; pickles the matches for analyze.py. Run (from the repo root):

    python docs/calibration/why_check_differs/diag.py skidpad yolov8:docs/calibration/second_detector/yolov8_conenet_s4.onnx \
        low_light 2 0.552 REF_CHUNK0+REF_CHUNK1 5

Outputs: five_seeds.txt (5 weather seeds), one_seed_pickled.txt (1 seed, pickled for analyze*.py).
"""
import json
import sys

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.lab.calibration.frame_ap import frame_matches
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.scoring import small_rule
from weather_gym.weather import make
from weather_gym.weather.presets import load_presets

scen, det_spec, cond, sev = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
ks = [float(x) for x in sys.argv[5].split(",")]
sets = sys.argv[6].split(",")  # folders
W = int(sys.argv[7]) if len(sys.argv) > 7 else 3
det = load_detector(None if det_spec == "shipped" else det_spec)
t = load_presets(None)["presets"][cond][sev]
table = {k: v for k, v in t["effects"][0].items() if k != "k"}
name = table.pop("name")
target = t["measured_relative"]
out = {}
for spec in sets:
    folders, _, lim = spec.partition(":")
    ims, depths, gts, groups, states = [], [], [], [], []
    for folder in folders.split("+"):
        ds = load_coco(folder, cache_images=True)
        n0 = len(ds) if not lim else int(lim)
        recs = [ds.record(j) for j in range(n0)]
        ims += [ds.image(j) for j in range(n0)]
        depths += [ds.depth(j) for j in range(n0)]
        gts += [ds.gt(j) for j in range(n0)]
        groups += [(folder, r.get("episode", j)) for j, r in enumerate(recs)]
        for r in recs:
            st = {"speed": float(r["speed"]), "yaw_rate": float(r["yaw_rate"])}
            c = CameraConfig(**r["camera"])
            st.update(exposure_s=c.exposure_s, fx=c.fx)
            states.append(st)
    n = len(ims)
    rule = small_rule(ds, det)
    mbh = None if rule is None else rule.min_height_px
    cd = det.detect_batch(ims, score_threshold=0.05) if False else [det.detect_batch([im], score_threshold=0.05)[0] for im in ims]
    clear = frame_matches(gts, cd, groups=groups, min_box_height=mbh)
    cm = clear.map50()
    sc_clear = None
    res = {"n": n, "episodes": clear.n_groups, "clear": cm, "clear_scoring": sc_clear, "cones": int(clear.npos.sum())}
    for k in ks:
        eff = make(name, k=k, **table)
        per = []
        mats = []
        alld = []
        for w in range(W):
            seeds = np.random.SeedSequence([w, 99]).generate_state(n, dtype=np.uint32)
            dd = []
            for j in range(n):
                sd = int(seeds[j])
                eff.reset(sd)
                im = eff(ims[j], depth=depths[j], state=dict(states[j]), rng=np.random.default_rng(sd))
                dd.append(det.detect_batch([im], score_threshold=0.05)[0])
            m = frame_matches(gts, dd, groups=groups, min_box_height=mbh)
            mats.append(m)
            alld.append(dd)
            per.append(m.map50() / cm)
        rng = np.random.default_rng(7)
        G = clear.n_groups
        wts = rng.multinomial(G, np.full(G, 1 / G), size=300).astype(float)
        c = clear.map50_many(wts)
        boots = [mats[w].map50_many(wts) / c for w in range(W)]
        se_frames = float(np.mean([np.std(b, ddof=1) for b in boots]))
        import pickle
        pickle.dump({"clear": clear, "mats": mats, "gts": gts, "groups": groups, "cd": cd, "dets": alld, "mbh": mbh}, open(f"scratch/mats_{abs(hash(spec))}_{k}.pkl", "wb"))
        res[str(k)] = {"rel_per_seed": [round(x, 4) for x in per], "mean": round(float(np.mean(per)), 4),
                       "sd_seeds": round(float(np.std(per, ddof=1)), 4) if W > 1 else None,
                       "boot_se_one_seed": round(se_frames, 4)}
        print(spec, k, res[str(k)], flush=True)
    out[spec] = res
    print(spec, {k: v for k, v in res.items() if not k[0].isdigit()}, flush=True)
print("target", target)
print(json.dumps(out))
