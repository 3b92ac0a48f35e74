"""Each test's grid coloured as Euro NCAP result sheets colour it, SV and V2I side by side.

Rows are the ego's test speeds (slowest at the top, as on the result sheets), columns the impact points;
a cell shows its colour band and its relative impact speed (km/h, blank when avoided). Extended-range
cells are hatched. Drawing only: the numbers come from ncap.csv.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

#: Fill colours of the bands (RGB hex), close to the result sheets'.
BAND_FILL = {
    "green": "#38a800",
    "yellow": "#ffd500",
    "orange": "#ff8c00",
    "brown": "#8b4513",
    "red": "#e00000",
}


#: A run that raised has no colour.
ERROR_FILL = "#b0b0b0"


def grid_figure(table: pd.DataFrame, path: Path) -> Path:
    """One row of panels per test, one column per condition; writes `path` (PNG) and returns it."""
    # matplotlib here, not at module top: the Agg backend is chosen when a figure is drawn, so importing
    # this module leaves the backend of a program that uses its own alone.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after the backend is chosen
    from matplotlib.patches import Patch, Rectangle  # with pyplot, after the backend

    nominal = table[table["variation"] == "nominal"].copy()
    if "lighting" in nominal:  # a night load case is a panel of its own: "CPNA night"
        night = nominal["lighting"] != "day"
        nominal.loc[night, "test"] = nominal.loc[night, "test"] + " " + nominal.loc[night, "lighting"]
    tests = list(dict.fromkeys(nominal["test"]))
    conditions = list(dict.fromkeys(nominal["condition"]))
    fig, axes = plt.subplots(
        len(tests),
        len(conditions),
        figsize=(3.4 * len(conditions) + 1.2, 2.6 * len(tests) + 0.6),
        squeeze=False,
    )
    for i, test in enumerate(tests):
        of_test = nominal[nominal["test"] == test]
        turns = of_test["turn"].fillna("") if "turn" in of_test else pd.Series("", index=of_test.index)
        row_keys = list(zip(turns, of_test["ego_speed_kmh"]))
        # Rows as run (the protocol's order); a turning test's rows carry their turn.
        speeds = list(dict.fromkeys(row_keys))
        points = sorted(of_test["impact_point_pct"].unique())
        for j, condition in enumerate(conditions):
            ax = axes[i][j]
            cells = of_test[of_test["condition"] == condition]
            for index, cell in cells.iterrows():
                x = points.index(cell["impact_point_pct"])
                y = len(speeds) - 1 - speeds.index(row_keys[of_test.index.get_loc(index)])
                ax.add_patch(
                    Rectangle(
                        (x, y),
                        1,
                        1,
                        facecolor=BAND_FILL.get(cell["colour"], ERROR_FILL),
                        edgecolor="black",
                        hatch="//" if cell["test_range"] == "extended" else None,
                    )
                )
                if not cell["avoided"] and cell["colour"] in BAND_FILL:
                    ax.text(x + 0.5, y + 0.5, f"{cell['impact_speed_kmh']:.0f}", ha="center", va="center")
            ax.set_xlim(0, len(points))
            ax.set_ylim(0, len(speeds))
            ax.set_xticks([k + 0.5 for k in range(len(points))], [f"{p:g}%" for p in points])
            labels = [f"{turn} {speed:g}".strip() for turn, speed in reversed(speeds)]
            ax.set_yticks([k + 0.5 for k in range(len(speeds))], labels)
            ax.set_title(f"{test} - {condition.upper()}")
            if j == 0:
                ax.set_ylabel("ego speed [km/h]")
            if i == len(tests) - 1:
                ax.set_xlabel("impact point [% of width from nearside]")
    handles = [Patch(facecolor=fill, edgecolor="black", label=name) for name, fill in BAND_FILL.items()]
    handles.append(Patch(facecolor="white", edgecolor="black", hatch="//", label="extended range"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), frameon=False)
    fig.suptitle("Euro NCAP pedestrian AEB grid: colour band, relative impact speed [km/h]")
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
