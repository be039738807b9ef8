"""Do the residuals of a recovery flag a near-Lambertian material that came back glossy?

For every case of a natural_light.py result folder: the image re-rendered under the
recovered material and map (from the case files), the log residual over the used pixels
(its median removed), and statistics of it and of its 5x5 box-smoothed version.

    .venv/bin/python benchmarks/misfit_residuals.py out/natural_light/validation/defaults val.json
"""
import sys, os, json, glob, numpy as np
from mi_dsbrdf.evaluation import experiment as ex
from mi_dsbrdf.evaluation.benchmark_cases import DATA, CACHE, NEAR_LAMBERTIAN, HIGHLIGHT_LIMIT
from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.inference.images import read_image
from mi_dsbrdf.inference.pixels import usable_pixels
from scipy.ndimage import uniform_filter
folder = sys.argv[1]
rows = []
for f in sorted(glob.glob(os.path.join(folder, "*.json"))):
    r = json.load(open(f))
    c = r["case"]
    if c.get("method", "dsbrdf") != "dsbrdf":
        continue
    H, W = c["map"]; res = c["res"]
    model = ex.loo_model(c["material"], CACHE)
    m = Material.from_basis(model.basis, np.array(r["material"]["psi"]), np.array(r["material"]["chromaticity"]))
    nbrdf = os.path.join(DATA, "merl", "merl_nbrdf_weights.npz")
    merl = {"type": "merl", "nbrdf": nbrdf, "material": c["material"]}
    truth = ex.downsample(read_image(os.path.join(DATA, "envmaps", c["probe"])), 2 * H, 2 * W)
    ts = ex.texels(merl, res, (2 * H, 2 * W))
    img = ex.render(ts, truth.reshape(-1, 3)).reshape(res, res, 3)
    keep = usable_pixels(ts.mask, img).reshape(res, res)
    L = np.load(f[:-5] + ".npz")["illumination"][1].astype(np.float64)
    view = ex.texels({"type": "dsbrdf"}, res, (H, W), samples=2).with_bsdf(ex.dsbrdf_bsdf(m))
    re = ex.render(view, L.reshape(-1, 3)).reshape(res, res, 3)
    e = 1e-3 * img[keep].mean()
    d = (np.log(np.maximum(re, 0) + e) - np.log(img + e)).mean(axis=2)
    d = d - np.median(d[keep])
    dk = np.where(keep, d, 0.0)
    w = uniform_filter(keep.astype(float), 5)
    sm = np.where(keep, uniform_filter(dk, 5) / np.maximum(w, 1e-9), 0.0)
    flat = r["truth_highlight_ratio"] < NEAR_LAMBERTIAN
    glossy = flat and r["highlight_ratio"] > HIGHLIGHT_LIMIT * r["truth_highlight_ratio"]
    row = dict(id=c["id"], flat=bool(flat), glossy=bool(glossy), med=float(np.median(np.abs(d[keep]))),
               rms_s=float(np.sqrt(np.mean(sm[keep] ** 2))), p95_s=float(np.percentile(np.abs(sm[keep]), 95)),
               frac01=float(np.mean(np.abs(sm[keep]) > 0.1)), frac02=float(np.mean(np.abs(sm[keep]) > 0.2)),
               ratio=float(np.sqrt(np.mean(sm[keep] ** 2)) / max(np.sqrt(np.mean(d[keep] ** 2)), 1e-9)),
               eq20=r["brdf_eq20_paper"], base=r["baseline"]["brdf_eq20_paper"])
    rows.append(row)
    print(json.dumps(row), flush=True)
json.dump(rows, open(sys.argv[2], "w"))
