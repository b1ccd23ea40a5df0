import json, sys
def load(f):
    d = json.load(open(f))
    out = {}
    for c in d["cells"]:
        if c["method"] == "hd" and c["guidance"] and not c.get("variant"):
            out[c["robot"]] = c
    return d, out
tot = {}
for label, files in [(a.split("=")[0], a.split("=")[1].split(",")) for a in sys.argv[1:]]:
    n = alone = fb = rs = rt = 0; meds = []
    for f in files:
        d, cells = load(f)
        P = d["context"]["problems"]
        for r, c in cells.items():
            n += P; alone += round(c["collision_free"] * P / 100)
            fb += round(c.get("net_fallback_rate", 0) * P / 100); rs += round(c.get("net_resample_rate", 0) * P / 100)
            rt += round(c.get("net_retry_rate", 0) * P / 100)
            meds.append(c["time_ms_median"])
    print(f"{label}: alone {alone}/{n} = {100*alone/n:.1f}%, retry {rt}, resample {rs}, fallback {fb} = {100*fb/n:.1f}%, medians {min(meds):.0f}-{max(meds):.0f} ms")
