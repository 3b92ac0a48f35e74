"""Heat map of pedestrian conflicts over a SUMO network, from the table of `python -m pedsafe_sumo.conflicts`.

    python -m pedsafe_sumo.conflicts.heatmap conflicts.parquet --net site.net.xml --out heatmap.png

The network is drawn from sumolib's lane shapes (lanes grey, crossings and walking areas lighter); the
interactions with an Amini conflict are counted in hexagonal cells at the place of their minimum
clearance (`x_m`, `y_m`), contacts marked on top. `--all` counts every interaction instead. Drawing
only: the measures come from the table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from pedsafe_sumo.conflicts.__main__ import site_net  # noqa: E402
from pedsafe_sumo.conflicts.places import NetError, PlaceFinder  # noqa: E402
from pedsafe_sumo.settings import UsageError  # noqa: E402

#: Size of a hexagonal cell across, m.
CELL_M = 5.0


def read_table(path: Path) -> pd.DataFrame:
    if not path.is_file():
        raise ValueError(f"table not found: {path}")
    try:
        table = pd.read_parquet(path) if path.suffix.lower() == ".parquet" else pd.read_csv(path)
    except Exception as exc:  # pandas raises many kinds on a file that is not a table
        raise ValueError(f"cannot read table {path}: {exc}") from None
    missing = [c for c in ("x_m", "y_m", "conflict", "collision") if c not in table.columns]
    if missing:
        raise ValueError(f"{path} is not a conflicts table: it lacks {', '.join(missing)}")
    return table


def draw_network(ax, net) -> tuple[float, float, float, float]:
    """Lanes as grey lines of their width (roads darker than walkways); returns the net's bounding box."""
    roads: list[Any] = []
    walks: list[Any] = []
    for edge in net.getEdges(withInternal=True):
        walking = edge.getFunction() in ("crossing", "walkingarea") or all(
            lane.allows("pedestrian") and not lane.allows("passenger") for lane in edge.getLanes()
        )
        for lane in edge.getLanes():
            (walks if walking else roads).append(lane.getShape())
    ax.add_collection(LineCollection(roads, colors="#9a9a9a", linewidths=1.6, zorder=1))
    ax.add_collection(LineCollection(walks, colors="#d0d0d0", linewidths=1.0, zorder=1))
    return net.getBBoxXY()[0] + net.getBBoxXY()[1]


def heatmap_figure(table: pd.DataFrame, net, title: str, every_interaction: bool = False):
    chosen = (
        table
        if every_interaction
        else table[table["conflict"].astype(bool) | table["collision"].astype(bool)]
    )
    fig, ax = plt.subplots(figsize=(9, 8), dpi=120)
    xmin, ymin, xmax, ymax = draw_network(ax, net)
    gridsize = max(10, int((xmax - xmin) / CELL_M))
    if len(chosen):
        cells = ax.hexbin(
            chosen["x_m"],
            chosen["y_m"],
            gridsize=gridsize,
            extent=(xmin, xmax, ymin, ymax),
            mincnt=1,
            cmap="inferno_r",
            alpha=0.85,
            zorder=2,
        )
        fig.colorbar(
            cells,
            ax=ax,
            shrink=0.7,
            label="interactions per cell" if every_interaction else "conflicts and contacts per cell",
        )
    hits = table[table["collision"].astype(bool)]
    if len(hits):
        ax.scatter(hits["x_m"], hits["y_m"], marker="x", s=40, color="#0050d0", zorder=3, label="contact")
        ax.legend(loc="upper right")
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (network frame)")
    ax.set_ylabel("y [m]")
    what = "interactions" if every_interaction else "Amini conflicts and contacts"
    ax.set_title(f"{title}\n{len(chosen)} {what} of {len(table)} pedestrian-vehicle interactions")
    fig.tight_layout()
    return fig


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m pedsafe_sumo.conflicts.heatmap", description=__doc__.splitlines()[0]
    )
    parser.add_argument(
        "table", type=Path, help="output of python -m pedsafe_sumo.conflicts (.csv or .parquet)"
    )
    parser.add_argument("--net", type=Path, help="the SUMO network the FCD ran on")
    parser.add_argument(
        "--site", metavar="NAME_OR_PATH", help="a pedsafe_sumo site whose network is the --net"
    )
    parser.add_argument("--out", type=Path, required=True, help="figure file (.png, .pdf or .svg)")
    parser.add_argument("--title", default="Pedestrian conflicts", help="figure title")
    parser.add_argument("--all", action="store_true", help="count every interaction, not only conflicts")
    args = parser.parse_args(argv)
    try:
        if args.out.suffix.lower() not in (".png", ".pdf", ".svg"):
            raise ValueError(f"--out must end in .png, .pdf or .svg, got {args.out}")
        table = read_table(args.table)
        try:
            args.net = site_net(args.net, args.site)
        except UsageError as exc:
            raise ValueError(str(exc)) from None
        if args.net is None:
            raise ValueError("give the network: --net NET.xml or --site NAME_OR_PATH")
        try:
            net = PlaceFinder(args.net).net
        except NetError as exc:
            raise ValueError(str(exc)) from None
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    fig = heatmap_figure(table, net, args.title, args.all)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_name(args.out.stem + ".tmp" + args.out.suffix)
    fig.savefig(tmp)
    plt.close(fig)
    tmp.replace(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
