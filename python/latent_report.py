"""The latent-space report (issue #6): autoencoder vs PCA-32 on the test split, a t-SNE map of
the latent space, latent vs weight interpolation strips and (optionally) Phong sampling with
predicted vs fitted parameters in the Veach scene.

    python python/latent_report.py [--nbrdfs DIR | --train-missing] [--out DIR] [--veach]

Inputs: a directory of NAME.nbrdf.json networks of the 100 MERL materials. By default they are
trained here from the SGD-synthesised tables (``--train-missing``: ``nbrdf synth`` + ``nbrdf
train`` + ``nbrdf fit-phong`` for every material not yet in the directory, ~100 x 15-25 s), or
pass the authors' networks imported with ``python -m nbrdf_mitsuba.import_keras``.
Everything else goes through the ``nbrdf`` CLI: ``ae train``, ``ae eval``, ``ae encode``,
``interpolate``, ``predictor train``, ``predict-phong``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def run(cmd: list, **kw) -> str:
    return subprocess.run([str(c) for c in cmd], check=True, capture_output=True, text=True, **kw).stdout


def train_missing(cli: Path, out: Path, samples: int) -> None:
    names = json.loads(run([cli, "list-materials", "--json"]))
    out.mkdir(parents=True, exist_ok=True)
    tables = out / "tables"
    tables.mkdir(exist_ok=True)
    for k, entry in enumerate(names):
        name = entry["name"]
        net = out / f"{name}.nbrdf.json"
        if net.exists():
            continue
        table = tables / f"{name}.binary"
        start = time.perf_counter()
        run([cli, "synth", "--model", "sgd", "--material", name, "-o", table])
        run([cli, "train", table, "-o", net, "--samples", samples])
        run([cli, "fit-phong", net])
        table.unlink()  # 35 MB each; the SGD fit regenerates it
        print(f"[{k + 1}/{len(names)}] {name}: {time.perf_counter() - start:.1f} s", flush=True)


# --- a numpy copy of the sphere renderer (metrics::render_sphere / latent::sphere) ----------


def sphere_inputs(size: int, light_theta: float):
    light = np.array([np.sin(light_theta), 0.0, np.cos(light_theta)])
    px = (2.0 * (np.arange(size) + 0.5) / size) - 1.0
    x, y = np.meshgrid(px, -px)
    r2 = x * x + y * y
    on = r2 < 1.0
    n = np.stack([x, y, np.sqrt(np.clip(1.0 - r2, 0.0, None))], -1)
    # Any tangent frame: the network input does not depend on the rotation about the normal.
    t = np.cross(n, np.array([0.0, 1.0, 0.0]))
    t /= np.linalg.norm(t, axis=-1, keepdims=True) + 1e-30
    b = np.cross(n, t)
    l_loc = np.stack([t @ light, b @ light, n @ light], -1)
    v_loc = np.stack([t[..., 2], b[..., 2], n[..., 2]], -1)
    h = l_loc + v_loc
    h /= np.linalg.norm(h, axis=-1, keepdims=True) + 1e-30
    sin_th = np.hypot(h[..., 0], h[..., 1])
    safe = sin_th > 1e-7
    cos_ph = np.where(safe, h[..., 0] / np.where(safe, sin_th, 1.0), 1.0)
    sin_ph = np.where(safe, h[..., 1] / np.where(safe, sin_th, 1.0), 0.0)
    tx = cos_ph * l_loc[..., 0] + sin_ph * l_loc[..., 1]
    ty = -sin_ph * l_loc[..., 0] + cos_ph * l_loc[..., 1]
    dx = h[..., 2] * tx - sin_th * l_loc[..., 2]
    dz = sin_th * tx + h[..., 2] * l_loc[..., 2]
    inp = np.stack([sin_th, np.zeros_like(sin_th), h[..., 2], dx, ty, dz], -1)
    lit = on & (l_loc[..., 2] > 0)
    return inp, np.where(lit, l_loc[..., 2], 0.0)


def render_network(path: Path, size: int = 64, light_deg: float = 45.0) -> np.ndarray:
    net = json.loads(Path(path).read_text())
    inp, cos = sphere_inputs(size, np.radians(light_deg))
    a = inp.reshape(-1, 6)
    for i, layer in enumerate(net["layers"]):
        w = np.array(layer["weights"], dtype=np.float64).reshape(layer["inputs"], layer["outputs"])
        a = a @ w + np.array(layer["bias"])
        if i < 2:
            a = np.maximum(a, 0.0)
    f = np.maximum(np.expm1(np.minimum(a, 80.0)), 0.0).reshape(size, size, 3)
    return f * cos[..., None]


def tone(img: np.ndarray) -> np.ndarray:
    return np.clip(np.maximum(img, 1e-12) ** (1 / 2.2), 0.0, 1.0)


def markdown_table(ev: dict) -> str:
    s = ev["summary"]
    lines = ["| method | MAE | RMSE | SSIM |", "|---|---|---|---|"]
    for key, label in (("ae", "autoencoder (32)"), ("pca", f"PCA-32 ({ev['pca']['tables']} tables)")):
        cells = [f"{s[key][m]['mean']:.4f} ± {s[key][m]['std']:.4f} (median {s[key][m]['median']:.4f})"
                 for m in ("mae", "rmse", "ssim")]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cli", type=Path, default=REPO / "target" / "release" / "nbrdf")
    p.add_argument("--nbrdfs", type=Path, default=REPO / "out" / "latent" / "nbrdfs")
    p.add_argument("--train-missing", action="store_true", help="train the networks not yet in --nbrdfs")
    p.add_argument("--samples", type=int, default=800_000)
    p.add_argument("--out", type=Path, default=REPO / "out" / "latent")
    p.add_argument("--ae", type=Path, help="an existing AE.json (default: OUT/ae.json, trained if missing)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--pca-tables", default="sgd", choices=["sgd", "nbrdf"])
    p.add_argument("--pair", nargs=2, help="materials to interpolate (default: two test materials)")
    p.add_argument("--steps", type=int, default=7)
    p.add_argument("--veach", action="store_true", help="also render the Veach scene, predicted vs fitted")
    p.add_argument("--veach-only", action="store_true",
                   help="only the Veach comparison (needs OUT/ae.json and OUT/predictor.json from an earlier run)")
    p.add_argument("--veach-spp", type=int, default=16)
    p.add_argument("--veach-gt-spp", type=int, default=512, help="spp of the converged MIS render")
    p.add_argument("--veach-seeds", type=int, default=4, help="renders (seeds) averaged per strategy")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.train_missing:
        train_missing(args.cli, args.nbrdfs, args.samples)
    ae = args.ae or args.out / "ae.json"
    if not ae.exists():
        print(run([args.cli, "ae", "train", "--nbrdfs", args.nbrdfs, "-o", ae, "--seed", args.seed]))
    split = json.loads(ae.read_text())["split"]
    if args.veach_only:
        veach(args, split)
        return 0

    # 1. AE vs PCA on the test split.
    ev = json.loads(run([args.cli, "ae", "eval", "--ae", ae, "--nbrdfs", args.nbrdfs,
                         "--pca-tables", args.pca_tables]))
    (args.out / f"ae_vs_pca_{args.pca_tables}.json").write_text(json.dumps(ev, indent=1))
    table = markdown_table(ev)
    rows = ["| material | AE MAE | PCA MAE | AE SSIM | PCA SSIM |", "|---|---|---|---|---|"]
    rows += [f"| {r['name']} | {r['ae']['mae']:.4f} | {r['pca']['mae']:.4f} | {r['ae']['ssim']:.3f} | "
             f"{r['pca']['ssim']:.3f} |" for r in ev["test"]]
    (args.out / f"ae_vs_pca_{args.pca_tables}.md").write_text(table + "\n\n" + "\n".join(rows) + "\n")
    print(table)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # 2. t-SNE of the codes.
    names = sorted(f.name[: -len(".nbrdf.json")] for f in args.nbrdfs.glob("*.nbrdf.json"))
    codes = np.array([json.loads(run([args.cli, "ae", "encode", "--ae", ae, args.nbrdfs / f"{n}.nbrdf.json"]))
                      for n in names])
    from sklearn.manifold import TSNE

    xy = TSNE(n_components=2, perplexity=15, random_state=args.seed, init="pca").fit_transform(codes)
    test = np.array([n in split["test"] for n in names])
    fig, ax = plt.subplots(figsize=(10, 8))
    ax.scatter(xy[~test, 0], xy[~test, 1], c="tab:blue", s=18, label="train")
    ax.scatter(xy[test, 0], xy[test, 1], c="tab:red", marker="*", s=80, label="test")
    for (x, y), n in zip(xy, names):
        ax.annotate(n, (x, y), fontsize=5, alpha=0.7)
    ax.legend()
    ax.set_title("t-SNE of the 32-value autoencoder codes")
    fig.savefig(args.out / "latent_tsne.png", dpi=150, bbox_inches="tight")
    plt.close(fig)

    # 3. Interpolation strips.
    a, b = args.pair or (split["test"][0], split["test"][-1])
    interp = args.out / "interp"
    run([args.cli, "interpolate", "--ae", ae, args.nbrdfs / f"{a}.nbrdf.json", args.nbrdfs / f"{b}.nbrdf.json",
         "--steps", args.steps, "-o", interp])
    fig, axes = plt.subplots(2, args.steps, figsize=(1.6 * args.steps, 3.6))
    for row, kind in enumerate(("latent", "weights")):
        for i in range(args.steps):
            img = tone(render_network(interp / f"{kind}_{i:02d}.nbrdf.json"))
            axes[row, i].imshow(img)
            axes[row, i].set_xticks([])
            axes[row, i].set_yticks([])
            if i == 0:
                axes[row, i].set_ylabel(kind, fontsize=9)
    fig.suptitle(f"{a} → {b}: latent (top) vs weight (bottom) interpolation")
    fig.savefig(args.out / "interpolation.png", dpi=150, bbox_inches="tight")
    plt.close(fig)

    # 4. Predictor: fitted vs predicted on the test split.
    pred = args.out / "predictor.json"
    if not pred.exists():
        print(run([args.cli, "predictor", "train", "--ae", ae, "--nbrdfs", args.nbrdfs, "-o", pred]))
    predicted_dir = args.out / "predicted"
    predicted_dir.mkdir(exist_ok=True)
    lines = ["| material | fitted n | predicted n | fitted w | predicted w |", "|---|---|---|---|---|"]
    for n in split["test"]:
        src = args.nbrdfs / f"{n}.nbrdf.json"
        dst = predicted_dir / f"{n}.nbrdf.json"
        run([args.cli, "predict-phong", "--ae", ae, "--predictor", pred, src, "-o", dst])
        fitted = json.loads(src.read_text()).get("sampling")
        if fitted is None or fitted.get("source") != "fit":
            fitted_dir = args.out / "fitted"
            fitted_dir.mkdir(exist_ok=True)
            run([args.cli, "fit-phong", src, "-o", fitted_dir / f"{n}.nbrdf.json"])
            fitted = json.loads((fitted_dir / f"{n}.nbrdf.json").read_text())["sampling"]
        s = json.loads(dst.read_text())["sampling"]
        lines.append(f"| {n} | {fitted['exponent']:.1f} | {s['exponent']:.1f} | {fitted['specular_weight']:.3f} | "
                     f"{s['specular_weight']:.3f} |")
    (args.out / "predicted_vs_fitted.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    if args.veach:
        veach(args, split)
    return 0


def veach(args, split) -> None:
    """Veach scene, pure BSDF sampling, `nbrdf` with Phong sampling from fitted vs predicted
    parameters at equal spp: RMSE against a converged MIS render of the same network, averaged
    over several seeds (single renders of this scene are heavy-tailed)."""
    import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
    import mitsuba as mi
    from tqdm import tqdm

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from veach_scene import plate_mask, veach_scene_dict

    mi.set_variant("llvm_ad_rgb")
    nbrdf_mitsuba.register()
    seeds = range(args.veach_seeds)
    # Errors on the plates only: elsewhere the images are the same diffuse scene, and the
    # anti-aliased edges of the bright lights would swamp the plates' sampling noise.
    plates = plate_mask(mi.load_dict(veach_scene_dict({"type": "diffuse"}, resolution=(192, 128))))
    lines = [f"Veach scene, pure BSDF sampling, 192x128, {args.veach_spp} spp, RMSE on the plates against "
             f"{args.veach_gt_spp} spp MIS, mean over {len(seeds)} seeds.", "",
             "| material | fitted n, w | predicted n, w | RMSE fitted | RMSE predicted | cosine | predicted / fitted |",
             "|---|---|---|---|---|---|---|"]
    ratios = []
    for n in tqdm(split["test"], desc="veach: predicted vs fitted", unit="material"):
        fitted = args.out / "fitted" / f"{n}.nbrdf.json"
        if not fitted.exists():
            fitted = args.nbrdfs / f"{n}.nbrdf.json"
        predicted = args.out / "predicted" / f"{n}.nbrdf.json"

        def render(path, spp, seed, integrator="bsdf", sampling="phong"):
            d = veach_scene_dict({"type": "nbrdf", "filename": str(path), "sampling": sampling},
                                 integrator=integrator, resolution=(192, 128), spp=spp, seed=seed)
            return np.array(mi.render(mi.load_dict(d), spp=spp))

        gt = render(fitted, args.veach_gt_spp, 10_000, "mis")

        def rmse(path, sampling="phong"):
            return float(np.mean([np.sqrt(np.mean((render(path, args.veach_spp, s, sampling=sampling) - gt)[plates] ** 2))
                                  for s in seeds]))

        r_fit, r_pred, r_cos = rmse(fitted), rmse(predicted), rmse(fitted, "cosine")
        ratios.append(r_pred / r_fit)
        lobe = [json.loads(Path(p).read_text())["sampling"] for p in (fitted, predicted)]
        lines.append(f"| {n} | {lobe[0]['exponent']:.3g}, {lobe[0]['specular_weight']:.2f} | "
                     f"{lobe[1]['exponent']:.3g}, {lobe[1]['specular_weight']:.2f} | {r_fit:.4g} | {r_pred:.4g} | "
                     f"{r_cos:.4g} | {r_pred / r_fit:.2f} |")
    lines += ["", f"predicted / fitted: median {np.median(ratios):.2f}, mean {np.mean(ratios):.2f}, "
              f"within 1.25x for {sum(r <= 1.25 for r in ratios)} of {len(ratios)} materials."]
    (args.out / "veach_predicted_vs_fitted.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
