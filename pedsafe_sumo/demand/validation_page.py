"""The measured part of the demand validation page (docs/demand_validation.md) and its ECDF figures.

One block per site between comment markers, so that validating one site rewrites only that site's
numbers and keeps the page's hand-written explanation.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # for the annotations only: validate imports this module
    from pedsafe_sumo.demand.validate import Comparison, Run

MEASURED_BEGIN = "<!-- measured:begin (written by python -m pedsafe_sumo.demand.validate) -->"
MEASURED_END = "<!-- measured:end -->"


def plot_ecdfs(comparisons: list[Comparison], figures_dir: Path, prefix: str, title: str) -> list[Path]:
    """One ECDF-vs-fit PNG per comparison (matplotlib Agg: no display needed)."""
    # Imported here: matplotlib costs a second at import, and the Agg backend is chosen before pyplot loads.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after the backend is chosen

    figures_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for comp in comparisons:
        fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
        if comp.n:
            x = np.sort(comp.samples)
            ax.step(x, np.arange(1, x.size + 1) / x.size, where="post", label=f"SUMO detectors (n={comp.n})")
            grid = np.linspace(0, np.quantile(x, 0.995) * 1.1, 400)
            ax.plot(grid, comp.cdf(grid), "--", label=f"fit: {comp.reference}")
        ax.set_xlabel(comp.name)
        ax.set_ylabel("cumulative share")
        ax.set_title(f"{title}\n{comp.name}: KS D = {comp.ks_distance:.3f}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right")
        fig.tight_layout()
        path = figures_dir / f"{prefix}_{comp.slug}.png"
        fig.savefig(path)
        plt.close(fig)
        paths.append(path)
    return paths


def measured_markers(site: str) -> tuple[str, str]:
    """The comments around a site's measured part of the validation page. Each site has its own, so that
    validating one site never overwrites another's numbers."""
    return (
        MEASURED_BEGIN.replace("measured:begin", f"measured:begin site={site}"),
        MEASURED_END.replace("measured:end", f"measured:end site={site}"),
    )


def measured_markdown(args, runs: list[Run], n_loops: dict[str, int], midblock_offset_m: float) -> str:
    """The measured block of `args.site`: the command, the loops, and per run its demand and comparisons."""
    begin, end = measured_markers(args.site)
    lines = [
        begin,
        f"Command: `python -m pedsafe_sumo.demand.validate --site {args.site} --duration {args.duration:g} "
        f"--seed {args.seed}" + (f" --params {args.params}" if args.params else "") + "`",
        "",
        f"Loops: {n_loops['midblock']} mid-block ({midblock_offset_m:g} m into each entering lane), "
        f"{n_loops['midlane']} mid-lane, {n_loops['junction']} inside the junction. Records of the first "
        f"{args.warmup:g} s are ignored. KS distance = sup |ECDF - fitted CDF|.",
        "",
    ]
    for run in runs:
        verdict = (
            "oversaturated: vehicles still waiting to enter at the end, approach speeds are queue speeds"
            if run.oversaturated
            else "the site carries this demand"
        )
        lines += [
            f"### {run.label} demand: {run.headway_rate_per_s:.4g} veh/s per entering lane "
            f"(mean headway {1 / run.headway_rate_per_s:.1f} s)",
            "",
            f"{run.n_vehicles} vehicles and {run.n_persons} pedestrians generated; {verdict} "
            f"(backlog {100 * run.backlog:.1f}% of the vehicles).",
            "SUMO: " + "; ".join(f"{k} {v}" for k, v in run.sim_stats.items()),
            *(f"\n**Not capacity:** {lane.line()}." for lane in run.stalled),
            "",
            "| measured | fit | n | KS distance | measured median | fit median |",
            "|---|---|---:|---:|---:|---:|",
        ]
        for c in run.comparisons:
            lines.append(
                f"| {c.name} | {c.reference} | {c.n} | {c.ks_distance:.3f} | {c.measured_median:.2f} | "
                f"{c.fitted_median:.2f} |"
            )
        lines.append("")
        lines += [f"![{fig.stem}](figures/{fig.name})" for fig in run.figures]
        lines.append("")
    lines.append(end)
    return "\n".join(lines)


def write_report(path: Path, measured: str, site: str) -> None:
    """Replace `site`'s measured part of the validation page, keeping its hand-written explanation and
    every other site's part; a site measured for the first time gets a section at the end."""
    begin, end = measured_markers(site)
    if path.is_file():
        text = path.read_text(encoding="utf-8")
        if begin in text and end in text:
            head, rest = text.split(begin, 1)
            tail = rest.split(end, 1)[1]
            path.write_text(head + measured + tail, encoding="utf-8")
            return
        section = f"\n\n## Measured: {site}\n\n{measured}\n"
        path.write_text(text.rstrip("\n") + section, encoding="utf-8")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"# Demand validation\n\n## Measured: {site}\n\n" + measured + "\n", encoding="utf-8")
