"""The library at a glance: ``index.json`` and ``index.csv`` (one row per material, failures
with their message), ``gallery.png`` (a contact sheet of the thumbnails) and ``index.html`` (a
static page that opens from disk, its table sortable by any column, errors included).
"""

from __future__ import annotations

import csv
import html
import io
import json
import math
import textwrap
from pathlib import Path

from nbrdf_tools.library.store import write_atomic
from nbrdf_tools.library.task import HIGHER_IS_BETTER, METRICS

COLUMNS = ("name", "status", "kind", *METRICS, "training_seconds", "epochs", "weights", "default_sampling",
           "wall_seconds", "network", "thumbnail", "source", "error")
LABELS = {"rmse_tonemapped": "RMSE (tone-mapped)", "ssim": "SSIM", "flip_hdr": "HDR-FLIP",
          "log_error_adaptive": "log error (adaptive)", "log_error_uniform": "log error (uniform)",
          "training_seconds": "training s", "wall_seconds": "wall s", "default_sampling": "sampling"}


def flat(row: dict) -> dict:
    """A row as the CSV's columns (None where a value does not apply)."""
    metrics = row.get("metrics") or {}
    files = row.get("files") or {}
    out = {}
    for column in COLUMNS:
        if column in METRICS:
            out[column] = metrics.get(column)
        elif column in ("network", "thumbnail"):
            out[column] = files.get(column)
        else:
            out[column] = row.get(column)
    return out


def index_json(rows: list[dict], meta: dict) -> str:
    return json.dumps({**meta, "materials": rows}, indent=1) + "\n"


def index_csv(rows: list[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if v is None else repr(v) if isinstance(v, float) else v) for k, v in flat(row).items()})
    return buffer.getvalue()


def _cell(column: str, value) -> str:
    if value is None:
        return '<td data-value="">-</td>'
    if isinstance(value, float):
        shown = f"{value:.4g}" if column not in ("training_seconds", "wall_seconds") else f"{value:.1f}"
        return f'<td class="num" data-value="{value!r}">{shown}</td>'
    if isinstance(value, int):
        return f'<td class="num" data-value="{value}">{value}</td>'
    return f'<td data-value="{html.escape(str(value))}">{html.escape(str(value))}</td>'


_SCRIPT = """
const table = document.getElementById("materials");
table.querySelectorAll("th[data-column]").forEach(th => {
  // The header's own position: the thumbnail column before it has no data-column.
  const index = th.cellIndex;
  th.addEventListener("click", () => {
    const ascending = th.dataset.order !== "asc";
    table.querySelectorAll("th").forEach(h => delete h.dataset.order);
    th.dataset.order = ascending ? "asc" : "desc";
    const body = table.tBodies[0];
    const key = row => row.cells[index].dataset.value;
    const rows = Array.from(body.rows);
    rows.sort((a, b) => {
      const x = key(a), y = key(b);
      if (x === "" || y === "") return (x === "") - (y === "");  // missing values last
      const nx = Number(x), ny = Number(y);
      const order = (isNaN(nx) || isNaN(ny)) ? x.localeCompare(y) : nx - ny;
      return ascending ? order : -order;
    });
    rows.forEach(row => body.appendChild(row));
  });
});
"""


def index_html(rows: list[dict], meta: dict) -> str:
    columns = ["thumbnail", "name", "status", "kind", *METRICS, "training_seconds", "epochs", "weights",
               "default_sampling", "error"]
    heads = []
    for column in columns:
        if column == "thumbnail":
            heads.append("<th>source | network</th>")
            continue
        hint = " (higher is better)" if column in HIGHER_IS_BETTER else ""
        heads.append(f'<th data-column="{column}" title="sort{hint}">{html.escape(LABELS.get(column, column))}</th>')
    body = []
    for row in rows:
        values = flat(row)
        thumb = values.get("thumbnail")
        cells = [f'<td><img src="{html.escape(thumb)}" alt="{html.escape(row["name"])}"></td>' if thumb
                 else "<td></td>"]
        cells += [_cell(c, values.get(c)) for c in columns[1:]]
        body.append(f'<tr class="{html.escape(str(row.get("status")))}">' + "".join(cells) + "</tr>")
    failed = sum(r.get("status") != "ok" for r in rows)
    return "\n".join([
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        f"<title>nbrdf library: {len(rows)} materials</title>",
        "<style>body{font-family:sans-serif;margin:1em}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:2px 6px;font-size:13px}th[data-column]{cursor:pointer;background:#eee}"
        "th[data-order=asc]::after{content:' \\25B2'}th[data-order=desc]::after{content:' \\25BC'}"
        "td.num{text-align:right;font-variant-numeric:tabular-nums}tr.failed,tr.pending{background:#fdd}"
        "img{height:48px;image-rendering:pixelated}</style>",
        "</head>", "<body>",
        f"<h1>nbrdf library: {len(rows)} materials, {failed} not converted</h1>",
        f"<p>Command: <code>{html.escape(meta.get('command', ''))}</code>. Metrics of each network against its "
        "own source (spheres under five lights; the log error over adaptive and uniform directions). "
        "Click a column to sort.</p>",
        '<table id="materials">', "<thead><tr>" + "".join(heads) + "</tr></thead>",
        "<tbody>", *body, "</tbody>", "</table>",
        f"<script>{_SCRIPT}</script>", "</body>", "</html>", ""])


def gallery_png(rows: list[dict], out: Path, columns: int = 6) -> bytes:
    """A contact sheet: each material's thumbnail (source left, network right) with its name and
    tone-mapped RMSE, or its failure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image
    import matplotlib.pyplot as plt

    n = max(1, len(rows))
    columns = min(columns, n)
    lines = math.ceil(n / columns)
    fig, axes = plt.subplots(lines, columns, figsize=(2.6 * columns, 1.75 * lines), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, row in zip(axes.flat, rows):
        thumb = (row.get("files") or {}).get("thumbnail")
        if row.get("status") == "ok" and thumb and (out / thumb).is_file():
            ax.imshow(matplotlib.image.imread(out / thumb))
            m = row.get("metrics") or {}
            ax.set_title(f"{row['name'][:30]}\nRMSE {m.get('rmse_tonemapped', math.nan):.3f}  "
                         f"FLIP {m.get('flip_hdr', math.nan):.3f}", fontsize=7)
        else:
            ax.set_facecolor("#f4dede")
            ax.axis("on")
            ax.set_xticks([])
            ax.set_yticks([])
            reason = textwrap.fill(str(row.get("error") or row.get("status")), 44)[:200]
            ax.text(0.5, 0.5, reason, ha="center", va="center", fontsize=5, wrap=True, transform=ax.transAxes)
            ax.set_title(f"{row['name'][:30]}\n{str(row.get('status')).upper()}", fontsize=7, color="#a00")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return buffer.getvalue()


def write_all(out: Path, rows: list[dict], meta: dict) -> dict[str, Path]:
    """Writes the four index files (atomically); their paths."""
    paths = {"json": out / "index.json", "csv": out / "index.csv", "gallery": out / "gallery.png",
             "html": out / "index.html"}
    write_atomic(paths["json"], index_json(rows, meta))
    write_atomic(paths["csv"], index_csv(rows))
    write_atomic(paths["gallery"], gallery_png(rows, out))
    write_atomic(paths["html"], index_html(rows, meta))
    return paths
