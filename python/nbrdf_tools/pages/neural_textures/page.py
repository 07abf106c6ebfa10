"""docs/results/neural-textures.md from its stored measurements (no Mitsuba, no measuring)."""

from __future__ import annotations

from importlib import resources

from nbrdf_tools.common import stored_page

PAGE = "neural-textures"
#: What must hold (issue targets, stated on the page): the neural texture's error at most this
#: many times the per-material route's (blends), within this tone-mapped RMSE of a smooth textured
#: source, and at least this share of roughconductor's rays per second.
PER_MATERIAL_RATIO = 1.5
SMOOTH_RMSE = 0.02
SPEED_SHARE = 0.5


def template() -> str:
    return resources.files("nbrdf_tools.pages").joinpath("templates", f"{PAGE}.md").read_text(encoding="utf-8")


def _f(value, digits: int = 4) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _mib(n: int) -> str:
    return f"{n / 2**20:.2f} MiB" if n >= 2**20 else f"{n / 1024:.1f} KiB"


def quality_table(sources: list[dict]) -> dict:
    rows = []
    for s in sources:
        e, route = s["errors"], s["errors"].get("per_material")
        ratio = None if route is None else e["neural"]["rmse_tonemapped"] / max(route["rmse_tonemapped"], 1e-12)
        rows.append([s["name"], s["subset"], _f(e["neural"]["rmse_tonemapped"]), _f(e["neural"]["flip_hdr"]),
                     _f(route and route["rmse_tonemapped"]), _f(route and route["flip_hdr"]),
                     "–" if ratio is None else f"{ratio:.2f}x"])
    return {"columns": ["source", "set", "neural RMSE", "neural FLIP", "per-material RMSE", "per-material FLIP",
                        "neural / per-material RMSE"], "align": "llrrrrr", "rows": rows}


def speed_table(sources: list[dict]) -> dict:
    rows = []
    for s in sources:
        r = s["mrays_per_s"]
        rows.append([s["name"], f"{r['source']:.2f}", f"{r['neural']:.2f}", f"{r['roughconductor']:.2f}",
                     f"{r['neural'] / r['source']:.2f}x", f"{r['neural'] / r['roughconductor']:.2f}x"])
    return {"columns": ["source", "source Mrays/s", "neural Mrays/s", "roughconductor Mrays/s", "neural / source",
                        "neural / roughconductor"], "align": "lrrrrr", "rows": rows}


def cost_table(sources: list[dict]) -> dict:
    rows = []
    for s in sources:
        m = s["memory"]
        rows.append([s["name"], f"{s['resolution']}²", str(s["channels"]), f"{s['conversion_seconds']:.0f}",
                     _mib(m["decoder"]), _mib(m["texture"]), _mib(m["texture_file"]), _mib(m["source"])])
    return {"columns": ["source", "texture", "C", "conversion s", "decoder", "latent texture", "EXR file",
                        "source's textures"], "align": "lrrrrrrr", "rows": rows}


def scaling_table(rows: list[dict]) -> dict:
    return {"columns": ["source", "texture", "conversion s", "latent texture", "EXR file"], "align": "lrrrr",
            "rows": [[r["name"], f"{r['resolution']}²", f"{r['seconds']:.0f}", _mib(r["memory"]["texture"]),
                      _mib(r["memory"]["texture_file"])] for r in rows]}


def chi2_table(sources: list[dict]) -> dict:
    rows = []
    for s in sources:
        for row in s["chi2"]:
            rows.append([s["name"], f"({row['uv'][0]:.2f}, {row['uv'][1]:.2f})", f"{row['theta']:.1f}",
                         f"{row['p_value']:.3f}", "pass" if row["passed"] else "**fail**"])
    return {"columns": ["source", "texel (u, v)", "view θ (rad)", "p-value", "chi2 at 1%"], "align": "llrrl",
            "rows": rows}


def kitchen_table(kitchen: dict | None) -> dict:
    if not kitchen:
        return {"columns": ["kitchen"], "rows": [["not measured"]]}
    rows = [[k, _f(v["rmse_tonemapped"]), _f(v["flip_hdr"])] for k, v in kitchen["errors"].items()]
    return {"columns": ["render", "tone-mapped RMSE", "FLIP"], "align": "lrr", "rows": rows}


def headline(sources: list[dict]) -> str:
    """The targets against the test set's figures, one sentence each."""
    test = [s for s in sources if s["subset"] == "test"] or sources
    lines = []
    blends = [s for s in test if s["errors"].get("per_material")]
    if blends:
        worst = max(s["errors"]["neural"]["rmse_tonemapped"] / s["errors"]["per_material"]["rmse_tonemapped"]
                    for s in blends)
        lines.append(f"* Blends of measurements: the neural texture's error is at most {worst:.2f}x the "
                     f"per-material route's (target <= {PER_MATERIAL_RATIO}x).")
    smooth = [s for s in test if s["kind"] in ("principled", "conductor", "kitchen")]
    if smooth:
        worst = max(s["errors"]["neural"]["rmse_tonemapped"] for s in smooth)
        lines.append(f"* Smooth textured sources: the neural texture's tone-mapped RMSE is at most {worst:.4f} "
                     f"(target: within {SMOOTH_RMSE}).")
    share = min(s["mrays_per_s"]["neural"] / s["mrays_per_s"]["roughconductor"] for s in test)
    lines.append(f"* Speed: at least {share:.2f}x roughconductor's rays per second (target >= {SPEED_SHARE}x).")
    chi2 = [r for s in test for r in s["chi2"]]
    lines.append(f"* Sampling: {sum(r['passed'] for r in chi2)} of {len(chi2)} chi2 tests pass at 1% "
                 f"({len(chi2) // max(len(test), 1)} per source: texels and views).")
    return "\n".join(lines)


def page(data: dict, opening: str) -> str:
    sources = data["sources"]
    filled = {"tables": {"quality": quality_table(sources), "speed": speed_table(sources),
                         "cost": cost_table(sources), "chi2": chi2_table(sources),
                         "scaling": scaling_table(data.get("scaling", [])),
                         "kitchen": kitchen_table(data.get("kitchen"))},
              "texts": {"opening": opening, "headline": headline(sources), "settings": settings_text(data)}}
    return stored_page.fill(template(), filled)


def settings_text(data: dict) -> str:
    s = data["settings"]
    return (f"Renders: {s['size']}x{s['size'] * 3 // 4} pixels, {s['spp']} samples per pixel (the kitchen's "
            f"reference {s['spp'] * s['reference_factor']}), `{s['variant']}`; neural textures at `--resolution "
            f"{s['resolution']}`, the distiller's defaults otherwise. Machine: {data.get('machine', 'not recorded')}.")
