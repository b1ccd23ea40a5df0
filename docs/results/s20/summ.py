"""usage: python summ.py LABEL=a.json,b.json ...  (HD guided cells; counts over files and robots)"""
import json, sys
for label, files in [(a.split("=")[0], a.split("=")[1].split(",")) for a in sys.argv[1:]]:
    n = alone = fb = rs = rt = net = fl = 0; meds = []; per = {}
    for f in files:
        d = json.load(open(f)); P = d["context"]["problems"]
        for c in d["cells"]:
            if not (c["method"] == "hd" and c["guidance"] and not c.get("variant")):
                continue
            k = lambda key: round((c.get(key) or 0) * P / 100)
            n += P; a = k("collision_free"); alone += a
            fb += k("net_fallback_rate"); rs += k("net_resample_rate"); rt += k("net_retry_rate")
            net += k("net_collision_free"); fl += k("first_leg_rate")
            meds.append(c["time_ms_median"])
            pr = per.setdefault(c["robot"], [0, 0]); pr[0] += a; pr[1] += P
    robots = ", ".join(f"{r} {v[0]}/{v[1]}" for r, v in per.items())
    print(f"{label}: alone {alone}/{n} = {100*alone/n:.1f}% ({robots}); first leg {fl}; retry {rt}, resample {rs}, fallback {fb} = {100*fb/n:.1f}%; with net {net}/{n}; medians {min(meds):.0f}-{max(meds):.0f} ms")
