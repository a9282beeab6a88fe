"""Regenerate assets/presets/*.toml (run from the repository root: python tools/make_presets.py).

The TOML files are the source of truth; this script records how they were made."""
from leafview.core.params import parse_params

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


# -- rippled and bent leaves (Geng, Hu & Zhang 2014) ------------------------------------------------------
def R(name, rows, ripple, bending=None, jitter=None, mat=None, **shape):
    rows = [[v, x, 0.0] for v, x in rows]
    d = {"schema": 1, "name": name,
         "shape": {"a1": list(shape.get("a1", (0, 1/3, 0))), "a2": list(shape.get("a2", (0, 2/3, 0))),
                   "silhouette": rows, "zf": list(shape.get("zf", (0, 0, 0))), "zg": list(shape.get("zg", (0, 0, 0)))},
         "material": {**G, **(mat or {})}, "ripple": {"enabled": True, **ripple}}
    if bending:
        d["bending"] = bending
    if jitter:
        d["jitter"] = {"enabled": True, **jitter}
    parse_params(d).save(f"assets/presets/{name}.toml")


# the paper's maize leaf: β = 1, k = 0.3 on both sides, θ = 8 (left) and 10 (right)
R("maize", [(0.08, 0.065), (0.5, 0.06), (0.92, 0.03)],
  {"beta": 1.0, "seed": 3, "veins": 80.0, "amplitude": [0.02, 0.02], "fluctuation": [0.0, 0.0],
   "interval": [0.3, 0.3], "phase": [8.0, 10.0]},
  bending={"load": 6.0, "twist": 25.0}, zf=(0.004, 0.005, 0.003), zg=(0.006, 0.008, 0.004),
  mat={"front": [0.07, 0.2, 0.03], "back": [0.16, 0.3, 0.07]})
R("holly", [(0.15, 0.42), (0.5, 0.46), (0.85, 0.3)],
  {"beta": 2.0, "seed": 11, "veins": 32.0, "amplitude": [0.06, 0.06], "fluctuation": [0.0, 0.0],
   "interval": [0.35, 0.35], "phase": [3.0, 5.5]},
  jitter={"amplitude": 0.015, "density": 14.0, "seed": 4},
  mat={"front": [0.015, 0.07, 0.02], "back": [0.09, 0.16, 0.05], "translucency": 0.15})
R("beech", [(0.12, 0.5), (0.42, 0.44), (0.78, 0.17)],
  {"beta": 2.5, "seed": 21, "veins": 40.0, "amplitude": [0.03, 0.03], "fluctuation": [0.1, 0.1],
   "interval": [0.3, 0.3], "phase": [1.0, 1.7]},
  zf=(0.01, 0.015, 0.01), zg=(0.015, 0.02, 0.01), mat={"front": [0.09, 0.24, 0.03]})
R("willow", [(0.12, 0.13), (0.45, 0.12), (0.8, 0.05)],
  {"beta": 1.5, "seed": 8, "veins": 40.0, "amplitude": [0.008, 0.008], "fluctuation": [0.3, 0.3],
   "interval": [0.25, 0.25], "phase": [2.0, 6.0]},
  bending={"load": 16.0, "twist": 15.0, "petiole_length": 0.06, "petiole_stiffness": 2.0},
  zf=(0.005, 0.006, 0.004), zg=(0.008, 0.01, 0.006), mat={"front": [0.06, 0.17, 0.04], "back": [0.2, 0.3, 0.14]})
