"""Regenerate assets/presets/*.toml (run from the repository root: python tools/make_presets.py).

The TOML files are the source of truth; this script records how they were made."""
from leafview.model.params import LeafParams, parse_params
G = dict(front=[0.045, 0.15, 0.025], back=[0.13, 0.25, 0.06], translucency=0.35)
def P(name, rows, a1=(0, 1/3, 0), a2=(0, 2/3, 0), zf=(0,0,0), zg=(0,0,0), zs=None, jitter=None, mat=None):
    rows = [[v, x, (zs[i] if zs else 0.0)] for i, (v, x) in enumerate(rows)]
    d = {"schema": 1, "name": name, "shape": {"a1": list(a1), "a2": list(a2), "silhouette": rows, "zf": list(zf), "zg": list(zg)},
         "material": {**G, **(mat or {})}}
    if jitter: d["jitter"] = {"enabled": True, **jitter}
    p = parse_params(d); p.save(f"assets/presets/{name}.toml")
P("elliptic", [(0.2, 0.36), (0.5, 0.44), (0.8, 0.36)], zf=(0.015,0.02,0.015), zg=(0.02,0.03,0.02))
P("ovate", [(0.12, 0.52), (0.4, 0.46), (0.75, 0.16)], zf=(0.01,0.015,0.01), zg=(0.015,0.02,0.01))
P("obovate", [(0.25, 0.16), (0.6, 0.46), (0.88, 0.52)], zf=(0.01,0.015,0.01), zg=(0.015,0.02,0.01))
P("lanceolate", [(0.15, 0.22), (0.38, 0.19), (0.72, 0.07)], zf=(0.008,0.01,0.005), zg=(0.01,0.012,0.006), mat={"front": [0.035, 0.13, 0.03]})
P("oblanceolate", [(0.28, 0.07), (0.62, 0.19), (0.85, 0.22)], zf=(0.005,0.01,0.008), zg=(0.006,0.012,0.01))
P("linear", [(0.04, 0.09), (0.5, 0.065), (0.96, 0.09)], a1=(0, 1/3, 0.02), a2=(0, 2/3, 0.03), mat={"front": [0.06, 0.17, 0.03]})
P("oblong", [(0.04, 0.4), (0.5, 0.3), (0.96, 0.4)], zf=(0.01,0.015,0.01), zg=(0.015,0.02,0.015))
P("orbicular", [(0.01, 0.39), (0.5, 0.815), (0.99, 0.39)], zf=(0.02,0.03,0.02), zg=(0.03,0.04,0.03), mat={"front": [0.05, 0.17, 0.03]})
P("deltoid", [(0.03, 0.56), (0.35, 0.34), (0.7, 0.14)])
P("rhomboidal", [(0.22, 0.2), (0.45, 0.62), (0.7, 0.16)])
P("acuminate", [(0.15, 0.6), (0.45, 0.36), (0.62, 0.0)], a2=(0, 2/3, -0.03), zs=(0,0,-0.02), zf=(0.01,0.02,-0.01), zg=(0.01,0.02,-0.01), mat={"front": [0.03, 0.12, 0.035]})
P("curled", [(0.2, 0.38), (0.5, 0.44), (0.8, 0.34)], a1=(0, 1/3, 0.12), a2=(0, 2/3, 0.12), zs=(0.16,0.2,0.14), zf=(0.04,0.05,0.04), zg=(0.09,0.11,0.08), mat={"front": [0.10, 0.17, 0.02], "back": [0.22, 0.27, 0.06]})
P("asymmetric", [(0.2, 0.36), (0.5, 0.42), (0.8, 0.3)], a1=(0.14, 1/3, 0), a2=(0.1, 2/3, 0), zf=(0.01,0.015,0.01), zg=(0.015,0.02,0.015))
P("serrate", [(0.18, 0.42), (0.5, 0.42), (0.8, 0.26)], zf=(0.01,0.015,0.01), zg=(0.015,0.02,0.015), jitter={"amplitude": 0.025, "density": 40.0, "seed": 7}, mat={"front": [0.04, 0.14, 0.03]})
